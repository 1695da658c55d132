"""Sensor models: rates, noise, outliers, dropouts, latency, upsampling, encoders, seeds."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.heart import make_scenario
from rhmpc.sim.sensors import (
    SENSORS,
    Dropouts,
    EchoOutliers,
    Encoder,
    Latency,
    SampleStream,
    Sensor,
    UltrasoundSettings,
    Upsample,
    WhiteNoise,
    WhiteSettings,
    ideal,
    sensor_from_name,
    sonomicrometry,
    ultrasound,
    white,
)


@pytest.fixture(scope="module")
def source():
    return make_scenario("fixed-a2-top", duration=120.0).source


def _error(stream: SampleStream, source) -> np.ndarray:
    return stream.z - source.position(stream.t)


@pytest.mark.parametrize("rate", [257.0, 404.0])
def test_white_rate_and_accuracy(source, rate: float) -> None:
    sensor = white(WhiteSettings(rate=rate, outliers=None))
    s = sensor.measure(source, 60.0, np.random.default_rng(0))
    assert len(s) == int(60 * rate) + 1
    np.testing.assert_allclose(np.diff(s.t), 1 / rate, rtol=1e-9)
    np.testing.assert_array_equal(s.arrival, s.t)
    err = _error(s, source)
    sigma = 0.25e-3 / np.sqrt(3)
    np.testing.assert_allclose(err.std(axis=0), sigma, rtol=0.05)
    assert np.sqrt(np.mean(np.sum(err ** 2, axis=1))) == pytest.approx(0.25e-3, rel=0.05)
    assert abs(err.mean()) < 1e-5


def test_echo_outliers_are_short_jumps_of_millimetres(source) -> None:
    outliers = EchoOutliers(rate=0.5, amplitude=(3e-3, 5e-3), duration=(2e-3, 8e-3))
    sensor = white(WhiteSettings(rate=404.0, accuracy=0.0, outliers=outliers))
    s = sensor.measure(source, 100.0, np.random.default_rng(1))
    jump = np.linalg.norm(_error(s, source), axis=1)
    hit = jump > 1e-6
    assert np.all((jump[hit] > 3e-3 - 1e-9) & (jump[hit] < 5e-3 + 1e-9))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], hit.astype(int), [0]])))
    runs = (edges[1::2] - edges[::2]) / 404.0
    assert 25 <= runs.size <= 80  # Poisson(50)
    assert runs.max() <= 8e-3 + 2 / 404.0  # a few milliseconds
    assert 0.001 < hit.mean() < 0.02  # occasional


def test_default_white_has_occasional_outliers(source) -> None:
    s = white().measure(source, 120.0, np.random.default_rng(5))
    big = np.linalg.norm(_error(s, source), axis=1) > 1.5e-3
    assert 0 < big.sum() < 0.01 * len(s)


def test_ultrasound_noise_rate_and_latency(source) -> None:
    s = ultrasound().measure(source, 100.0, np.random.default_rng(2))
    assert s.rate == 28.0
    assert len(s) == 100 * 28 + 1
    np.testing.assert_allclose(s.arrival - s.t, 0.068, atol=1e-12)
    np.testing.assert_allclose(_error(s, source).std(axis=0), 1.3e-3, rtol=0.08)
    slow = ultrasound(UltrasoundSettings(latency=0.132)).measure(source, 5.0,
                                                                  np.random.default_rng(2))
    np.testing.assert_allclose(slow.arrival - slow.t, 0.132, atol=1e-12)
    assert ultrasound(UltrasoundSettings(latency=0.039)).latency == pytest.approx(0.039)


def test_stream_availability_follows_arrival(source) -> None:
    s = ultrasound().measure(source, 2.0, np.random.default_rng(0))
    assert s.latest(0.05) is None  # the first frame arrives at 68 ms
    t, z = s.latest(0.07)
    assert t == 0.0 and z.shape == (3,)
    assert int(s.available(1.0)) == int(np.floor((1.0 - 0.068) * 28)) + 1


def test_dropouts_last_between_bounds(source) -> None:
    drop = Dropouts(rate=0.2, duration=(0.12, 3.0))
    s = Sensor(200.0, (drop,)).measure(source, 300.0, np.random.default_rng(4))
    missing = np.isnan(s.z[:, 0])
    assert np.array_equal(missing, np.isnan(s.z).any(axis=1))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], missing.astype(int), [0]])))
    runs = (edges[1::2] - edges[::2]) / 200.0
    assert runs.size >= 20
    assert runs.min() >= 0.12 - 0.01
    assert runs.max() <= 2 * 3.0  # overlapping events may merge
    ok = ~missing
    np.testing.assert_allclose(s.z[ok], source.position(s.t[ok]), atol=1e-15)
    iv = drop.intervals(0.0, 1e4, np.random.default_rng(0))
    length = iv[:, 1] - iv[:, 0]
    assert length.min() >= 0.12 and length.max() <= 3.0


def test_upsample_to_control_rate(source) -> None:
    raw = Sensor(257.0).measure(source, 2.0, np.random.default_rng(0))
    up = Upsample(2000.0).apply(raw, np.random.default_rng(0))
    assert up.rate == 2000.0
    np.testing.assert_allclose(np.diff(up.t), 5e-4, rtol=1e-9)
    np.testing.assert_array_equal(up.arrival, up.t)  # playback: no wait
    np.testing.assert_allclose(up.z, source.position(up.t), atol=5e-5)
    causal = Upsample(2000.0, causal=True).apply(raw, np.random.default_rng(0))
    wait = causal.arrival - causal.t
    assert wait.min() >= 0 and wait.max() <= 1 / 257 + 1e-12
    hold = Upsample(2000.0, method="hold").apply(raw, np.random.default_rng(0))
    k = np.searchsorted(raw.t, hold.t, side="right") - 1
    np.testing.assert_array_equal(hold.z, raw.z[k])
    s = sensor_from_name("sonomicrometry", upsample=2000.0)
    assert s.measure(source, 1.0, np.random.default_rng(0)).rate == 2000.0


def test_upsample_propagates_missing(source) -> None:
    raw = Sensor(100.0).measure(source, 1.0, np.random.default_rng(0))
    z = raw.z.copy()
    z[50] = np.nan
    up = Upsample(1000.0).apply(SampleStream(raw.t, z, raw.arrival, raw.rate), None)
    bad = np.isnan(up.z[:, 0])
    assert bad.any()
    assert np.all((up.t[bad] > 0.49 - 1e-9) & (up.t[bad] < 0.51 + 1e-9))


def test_stages_compose_in_order(source) -> None:
    sensor = Sensor(100.0, (WhiteNoise(1e-3), Latency(0.01))).with_stages(Latency(0.02))
    s = sensor.measure(source, 1.0, np.random.default_rng(0))
    np.testing.assert_allclose(s.arrival - s.t, 0.03)
    assert sensor.latency == pytest.approx(0.03)


def test_seeds_reproduce(source) -> None:
    for name in SENSORS:
        sensor = sensor_from_name(name, dropouts=Dropouts(rate=0.1))
        a = sensor.measure(source, 20.0, np.random.default_rng(11))
        b = sensor.measure(source, 20.0, np.random.default_rng(11))
        np.testing.assert_array_equal(a.z, b.z)
        np.testing.assert_array_equal(a.arrival, b.arrival)
    c = sonomicrometry().measure(source, 20.0, np.random.default_rng(12))
    d = sonomicrometry().measure(source, 20.0, np.random.default_rng(11))
    assert not np.array_equal(c.z, d.z)


def test_sensor_from_name() -> None:
    assert sensor_from_name("sonomicrometry").rate == 257.0
    assert sensor_from_name("sonomicrometry", rate=404).rate == 404.0
    us = sensor_from_name("ultrasound", latency=0.1, noise=2e-3)
    assert us.rate == 28.0 and us.latency == pytest.approx(0.1)
    assert ideal().rate == sensor_from_name("ideal").rate == 2000.0
    with pytest.raises(ValueError, match="sonomicrometry, white, ultrasound, video, ideal"):
        sensor_from_name("lidar")


def test_one_dimensional_source() -> None:
    src = make_scenario("mitral-1d").source
    s = ultrasound().measure(src, 10.0, np.random.default_rng(0))
    assert s.z.shape == (281, 1)
    sono = white(WhiteSettings(outliers=None), dim=1)
    err = sono.measure(src, 30.0, np.random.default_rng(0))
    assert np.std(_error(err, src)) == pytest.approx(0.25e-3, rel=0.05)


def test_invalid_settings() -> None:
    with pytest.raises(ValueError):
        WhiteNoise(-1.0)
    with pytest.raises(ValueError):
        Latency(-0.1)
    with pytest.raises(ValueError):
        Dropouts(duration=(0.0, 1.0))
    with pytest.raises(ValueError):
        Sensor(0.0)
    with pytest.raises(ValueError):
        Encoder(counts_per_rev=0)


def test_encoder_quantisation() -> None:
    enc = Encoder()
    assert enc.counts_per_rev == 4096
    delta = 2 * np.pi / 4096
    assert enc.resolution == pytest.approx(delta)
    q = np.random.default_rng(0).uniform(-2, 2, (1000, 3))
    qq = enc.quantize(q)
    assert qq.shape == q.shape
    assert np.max(np.abs(qq - q)) <= delta / 2 + 1e-15
    np.testing.assert_allclose(qq / delta, np.round(qq / delta), atol=1e-9)
    assert np.all(np.diff(enc.quantize(np.linspace(0, 0.1, 500))) >= 0)
    floor = Encoder(mode="floor").quantize(q)
    err = q - floor
    assert err.min() >= -1e-15 and err.max() < delta
    assert float(enc.quantize(0.0)) == 0.0
