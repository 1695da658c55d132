"""Chunked streams, running statistics and traces against their whole-array originals."""

import numpy as np
import pytest

from rhmpc.sim.loop.closed_loop import poi_truth
from rhmpc.sim.loop.metrics import RunningTracking, TickHistogram, rms
from rhmpc.sim.loop.streams import SourceTruth, StreamCursor
from rhmpc.sim.loop.trace import DecimatedTrace, TraceFile, read_trace
from rhmpc.sim.recordings import RecordedMotion
from rhmpc.sim.sensors import (
    Dropouts,
    Sensor,
    SonomicrometrySettings,
    Upsample,
    ideal,
    sonomicrometry,
)
from rhmpc.sim.sensors.playback import UpsampledSamples
from rhmpc.sim.sensors.stream import ArraySamples, SampledSamples
from tests.sim.loop.stand_ins import HarmonicHeart

TS = 0.5e-3



def tracking_metrics(error: np.ndarray, tau_mpc: np.ndarray, tau_total: np.ndarray) -> dict:
    """3-D position error RMS / max [mm] and RMS control effort [mN·m] over the given ticks.

    ``error`` is (n, 3) end-effector minus POI in metres; efforts are (n, nv) in N·m. The effort
    is the RMS over time of the Euclidean norm of the joint torque vector.
    """
    norm = np.linalg.norm(error, axis=1)
    return {
        "rms_error_mm": float(1e3 * rms(norm)),
        "max_error_mm": float(1e3 * np.nanmax(norm)) if norm.size else float("nan"),
        "rms_error_axis_mm": (1e3 * rms(error, axis=0)).tolist(),
        "rms_effort_mNm": float(1e3 * rms(np.linalg.norm(tau_mpc, axis=1))),
        "rms_total_torque_mNm": float(1e3 * rms(np.linalg.norm(tau_total, axis=1))),
    }


def raw_stream(latency=0.0):
    cfg = SonomicrometrySettings(dropouts=Dropouts(rate=0.5), latency=latency)
    return sonomicrometry(cfg).measure(HarmonicHeart(), 21.0, np.random.default_rng(4))


def blocks(samples, size):
    parts = [samples.block(a, min(a + size, len(samples))) for a in range(0, len(samples), size)]
    return [np.concatenate([p[i] for p in parts]) for i in range(3)]


@pytest.mark.parametrize("upsample", [Upsample(2000.0), Upsample(2000.0, causal=True),
                                      Upsample(2000.0, method="hold")])
@pytest.mark.parametrize("latency", [0.0, 0.013])
def test_upsampled_blocks_are_the_whole_stream_to_the_bit(upsample, latency):
    raw = raw_stream(latency)
    whole = upsample.apply(raw, np.random.default_rng(0))
    lazy = UpsampledSamples(raw, upsample)
    assert len(lazy) == len(whole)
    for size in (4096, 777):  # grid blocks as the cursor reads them, and odd ones
        t, z, arrival = blocks(lazy, size)
        np.testing.assert_array_equal(t, whole.t)
        np.testing.assert_array_equal(z, whole.z)
        np.testing.assert_array_equal(arrival, whole.arrival)


def newest_arrived(arrival: np.ndarray, n_ticks: int, Ts: float) -> np.ndarray:
    """Index of the newest sample arrived by each tick's time (−1 before the first)."""
    return np.searchsorted(arrival, np.arange(n_ticks) * Ts + 1e-12, side="right") - 1


def test_cursor_finds_the_newest_arrived_sample_of_the_whole_stream():
    raw = raw_stream(latency=0.011)
    whole = Upsample(2000.0).apply(raw, np.random.default_rng(0))
    n = round(20.0 / TS)
    expected = newest_arrived(whole.arrival, n, TS)
    cursor = StreamCursor(UpsampledSamples(raw, Upsample(2000.0)))
    for i in range(0, n, 15):
        j = cursor.newest(i * TS + 1e-12)
        assert j == expected[i]
        if j >= 0:
            t, z = cursor.sample(j)
            assert t == whole.t[j]
            np.testing.assert_array_equal(z, whole.z[j])


def test_sampled_source_is_a_stageless_sensor():
    src = HarmonicHeart()
    whole = ideal(2000.0).measure(src, 3.0, np.random.default_rng(0))
    lazy = SampledSamples(src, 2000.0, len(whole))
    t, z, arrival = blocks(lazy, 1000)
    np.testing.assert_array_equal(t, whole.t)
    np.testing.assert_array_equal(z, whole.z)
    np.testing.assert_array_equal(arrival, whole.arrival)
    assert lazy.index_at(whole.t[123]) == 123 and lazy.index_at(whole.t[123] - 1e-9) == 122


def test_source_truth_windows_are_poi_truth():
    src, n = HarmonicHeart(), 9001
    center, truth = poi_truth(src, n, TS)
    streamed = SourceTruth(src, n, TS, chunk=1000)
    # the mean is summed per chunk: its last bits may differ (measured ≤ 1e-19 m)
    np.testing.assert_allclose(streamed.center, center, rtol=0, atol=1e-18)
    got = np.concatenate([streamed.window(a, a + 700) for a in range(0, n, 700)])
    np.testing.assert_allclose(got, truth, rtol=0, atol=1e-18)


def test_recorded_truth_windows_interpolate_the_whole_stream():
    raw = raw_stream()
    whole = Upsample(2000.0).apply(raw, np.random.default_rng(0))
    n = round(20.0 / TS)
    target = RecordedMotion(whole.t, whole.z)
    _center, truth = poi_truth(target, n, TS)
    streamed = SourceTruth(UpsampledSamples(raw, Upsample(2000.0)), n, TS, chunk=3000)
    got = np.concatenate([streamed.window(a, a + 999) for a in range(0, n, 999)])
    assert np.isnan(truth).any()  # the dropouts
    np.testing.assert_array_equal(np.isnan(got), np.isnan(truth))
    np.testing.assert_allclose(got, truth, rtol=0, atol=1e-18)
    assert len(ArraySamples.of(whole)) == len(whole)


def test_tick_histogram_percentiles_to_its_resolution():
    rng = np.random.default_rng(1)
    ns = np.concatenate([rng.gamma(4.0, 5000.0, 200_000), [3e6, 5e6]]).astype(np.int64)
    hist = TickHistogram(resolution_ns=10)
    for part in np.array_split(ns, 37):
        hist.add(part)
    stats = hist.stats_us()
    for name, q in (("p50", 0.5), ("p99", 0.99), ("p999", 0.999)):
        exact = np.percentile(ns, 100 * q, method="inverted_cdf") / 1e3
        assert exact - 0.010 < stats[name] <= exact
    assert stats["max"] == 5e3 and stats["mean"] == pytest.approx(ns.mean() / 1e3, rel=1e-12)
    hist_all = TickHistogram(span_ns=1000)  # everything in the exact overflow list
    hist_all.add(ns)
    assert hist_all.stats_us()["p99"] == np.percentile(ns, 99, method="inverted_cdf") / 1e3


def test_running_tracking_is_tracking_metrics():
    rng = np.random.default_rng(2)
    error = rng.normal(scale=1e-4, size=(5000, 3))
    error[100:140, 1] = np.nan
    tau_mpc, tau = rng.normal(size=(5000, 3)), rng.normal(size=(5000, 3))
    running = RunningTracking()
    for sl in np.array_split(np.arange(5000), 7):
        running.add(error[sl], tau_mpc[sl], tau[sl])
    got, want = running.result(), tracking_metrics(error, tau_mpc, tau)
    for key, value in want.items():
        np.testing.assert_allclose(got[key], value, rtol=1e-13)


def chunks(n, size):
    for a in range(0, n, size):
        tick = np.arange(a, min(a + size, n))
        yield {"tick": tick, "ee": np.c_[tick, tick, tick] * 1.0}


def test_trace_file_holds_every_tick(tmp_path):
    path = tmp_path / "run.npz"
    trace = TraceFile(path)
    for c in chunks(10_001, 1995):
        trace.add(c)
    trace.close()
    back = read_trace(path)
    np.testing.assert_array_equal(back["tick"], np.arange(10_001))
    np.testing.assert_array_equal(back["ee"][:, 2], np.arange(10_001))


def test_decimated_trace_is_bounded_and_keeps_a_full_rate_tail():
    trace = DecimatedTrace(1_000_000, points=1000, tail=300)
    for c in chunks(1_000_000, 1995):
        trace.add(c)
    tick = trace.arrays()["tick"]
    assert tick.size <= 1000 + 300 and np.all(np.diff(tick) > 0)
    np.testing.assert_array_equal(tick[-300:], np.arange(1_000_000 - 300, 1_000_000))
    assert trace.stride == 1000 and tick[1] - tick[0] == 1000


def test_a_sensor_samples_its_source_in_chunks(monkeypatch):
    cfg = SonomicrometrySettings(dropouts=Dropouts(rate=0.5), latency=0.004)
    sensor = sonomicrometry(cfg)
    whole = sensor.measure(HarmonicHeart(), 30.0, np.random.default_rng(8))
    monkeypatch.setattr(Sensor, "CHUNK", 1000)
    chunked = sensor.measure(HarmonicHeart(), 30.0, np.random.default_rng(8))
    np.testing.assert_array_equal(chunked.t, whole.t)
    np.testing.assert_array_equal(chunked.arrival, whole.arrival)
    np.testing.assert_array_equal(np.isnan(chunked.z), np.isnan(whole.z))
    # the motion evaluated on shorter arrays: last-bit differences only (measured ≤ 1e-17 m)
    np.testing.assert_allclose(chunked.z, whole.z, rtol=0, atol=1e-17)
