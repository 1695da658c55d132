"""Synthetic heart-motion scenarios: API, replica statistics against the papers, speed, seeds."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy import signal

from rhmpc.sim.heart import (
    DEFAULT_SCENARIO,
    SCENARIOS,
    SPECS,
    Scenario,
    StaircaseProfile,
    make_scenario,
)
from rhmpc.sim.heart.analysis import motion_stats, peak_to_peak, rms_about_mean
from rhmpc.sim.heart.rr import STAIRCASE_LEVELS_HZ

TUNA_TABLE = {  # name: (p-p [mm], sensor rate [Hz], duration [s]) — Table I and footnote 1
    "fixed-a1-top": (12.19, 404.0, 235.0),
    "fixed-a2-top": (8.39, 257.0, 472.0),
    "varying-a1-top": (13.75, 404.0, 251.0),
    "varying-a3-top": (7.43, 404.0, 200.0),
    "varying-a1-side": (13.39, 404.0, 250.0),
    "varying-a3-side": (7.96, 404.0, 140.0),
}


def _record(sc: Scenario) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(round(sc.duration * sc.sensor_rate) + 1) / sc.sensor_rate
    return t, sc.source.position(t)


@pytest.fixture(scope="module")
def replicas() -> dict[str, Scenario]:
    return {name: make_scenario(name) for name in SCENARIOS if name in TUNA_TABLE}


@pytest.fixture(scope="module")
def clean() -> dict[str, Scenario]:
    """The periodic replicas (no physiological variability): the papers' line spectra."""
    return {name: make_scenario(name, variability="clean") for name in SCENARIOS
            if name in TUNA_TABLE}


def test_names_and_default() -> None:
    assert set(SCENARIOS) == {
        "fixed-a1-top", "fixed-a2-top", "varying-a1-top", "varying-a3-top",
        "varying-a1-side", "varying-a3-side", "mitral-1d", "arrhythmia-apb", "invivo-video"}
    assert DEFAULT_SCENARIO == "fixed-a2-top" == SCENARIOS[0]


def test_unknown_name_lists_valid_names() -> None:
    with pytest.raises(ValueError, match=r"fixed-a2-top.*mitral-1d"):
        make_scenario("fixed-a9-top")


def test_unknown_override_is_rejected() -> None:
    with pytest.raises(ValueError, match=r"unknown scenario override.*heartrate"):
        make_scenario("fixed-a2-top", heartrate=1.0)


@pytest.mark.parametrize("name", sorted(TUNA_TABLE))
@pytest.mark.slow
def test_replica_matches_tuna_table(replicas: dict[str, Scenario], name: str) -> None:
    pp_mm, rate, duration = TUNA_TABLE[name]
    sc = replicas[name]
    assert sc.sensor_rate == rate
    assert sc.duration == duration
    assert sc.source.dim == 3
    assert "replica" in sc.description
    _, p = _record(sc)
    assert peak_to_peak(p) * 1e3 == pytest.approx(pp_mm, rel=0.02)


@pytest.mark.parametrize("variability", ["clean", "default"])
@pytest.mark.slow
def test_fixed_a2_top_rms(replicas: dict[str, Scenario], clean: dict[str, Scenario],
                          variability: str) -> None:
    """§III-B: RMS 3.55 mm, with and without the physiological variability."""
    sc = (clean if variability == "clean" else replicas)["fixed-a2-top"]
    _, p = _record(sc)
    assert rms_about_mean(p) * 1e3 == pytest.approx(3.55, rel=0.02)
    assert peak_to_peak(p) * 1e3 == pytest.approx(8.39, rel=0.02)


def test_fixed_a2_top_frequencies(clean: dict[str, Scenario]) -> None:
    """§III-B, Fig. 2(A) of the clean replica: f_r ≈ 0.17 Hz (+0.33 Hz), f_h = 1.66 Hz and
    harmonics as tall narrow lines (the physiological variability broadens them)."""
    sc = clean["fixed-a2-top"]
    _, p = _record(sc)
    f, s = signal.welch(p, fs=sc.sensor_rate, nperseg=int(100 * sc.sensor_rate), axis=0)
    total = s.sum(axis=1)

    def peak(lo: float, hi: float) -> float:
        band = (f >= lo) & (f <= hi)
        return float(f[band][np.argmax(total[band])])

    assert abs(peak(0.1, 0.25) - 0.17) < 0.02
    assert abs(peak(0.25, 0.45) - 0.33) < 0.02
    f_h = peak(0.7, 3.0)
    assert abs(f_h - 1.66) < 0.02
    # fundamental and at least four harmonics clearly above the spectrum between them
    for k in range(1, 6):
        on = total[np.argmin(np.abs(f - k * f_h))]
        off = total[np.argmin(np.abs(f - (k + 0.5) * f_h))]
        assert on > 100 * off, f"harmonic {k} not visible"


def test_fixed_a1_top_frequency(clean: dict[str, Scenario]) -> None:
    sc = clean["fixed-a1-top"]
    stats = motion_stats(sc.source, sc.duration, sc.sensor_rate)
    assert stats.heart_rate[0] == stats.heart_rate[1]
    heart = [fp for fp in stats.peaks if 0.7 < fp < 3.0]
    assert abs(heart[0] - 1.58) < 0.02


@pytest.mark.parametrize("variability", ["clean", "default"])
def test_varying_a3_top_rms(replicas: dict[str, Scenario], clean: dict[str, Scenario],
                            variability: str) -> None:
    """§III-B: the varying-rate data set has p-p 7.43 mm and RMS 3.38 mm (measured with the
    variability: 3.32 mm, −1.8 %)."""
    _, p = _record((clean if variability == "clean" else replicas)["varying-a3-top"])
    assert rms_about_mean(p) * 1e3 == pytest.approx(3.38, rel=0.02)


@pytest.mark.parametrize("name", ["varying-a1-top", "varying-a3-top", "varying-a1-side",
                                  "varying-a3-side"])
def test_staircase_rates_are_spectral_peaks(clean: dict[str, Scenario], name: str) -> None:
    """Tuna Fig. 2(B): peaks at 1.58, 1.81, 2.03, 2.18, 2.42, 2.54 Hz (95–152 bpm)."""
    sc = clean[name]
    _, p = _record(sc)
    f, s = signal.welch(p, fs=sc.sensor_rate, nperseg=int(40 * sc.sensor_rate), axis=0)
    total = s.sum(axis=1)
    floor = np.median(total[(f > 1.3) & (f < 2.8)])
    for level in STAIRCASE_LEVELS_HZ:
        band = (f > level - 0.05) & (f < level + 0.05)
        i = np.argmax(total[band])
        assert abs(f[band][i] - level) < 0.02, (level, f[band][i])
        assert total[band][i] > 5 * floor, f"{level} Hz not a visible peak"


def test_staircase_profile_shape() -> None:
    t, rate = StaircaseProfile().knots(251.0)
    assert rate[0] == pytest.approx(1.58) and rate.max() == pytest.approx(2.54)
    assert rate[-1] == pytest.approx(1.58)
    assert t[1] == pytest.approx(39.5)  # 40 s at 95 bpm, then 1 s ramps
    sc = make_scenario("varying-a1-top", variability="clean")
    assert 60 * sc.source.phase.rate(np.array([20.0]))[0] == pytest.approx(94.8)
    assert 60 * sc.source.phase.rate(np.array([40 + 5 * 15 - 7.5]))[0] == pytest.approx(152.4)


def test_mitral_1d_matches_yuen() -> None:
    """Yuen 2009 §2: 20 mm travel, 210 mm/s, 3.8 m/s² at 76 bpm; peaks at 1.3/2.6/5.2 Hz."""
    sc = make_scenario("mitral-1d", variability="clean")
    assert sc.source.dim == 1 and sc.sensor_rate == 28.0
    assert 60 * sc.source.phase.rate(np.array([1.0]))[0] == pytest.approx(60.0)
    fast = make_scenario("mitral-1d", heart_rate=76 / 60, variability="clean")
    t = np.arange(0, 30, 1e-3)
    p = fast.source.position(t)[:, 0]
    assert np.ptp(p) * 1e3 == pytest.approx(20.0, rel=0.02)
    v = np.gradient(p, t)
    a = np.gradient(v, t)
    assert np.max(np.abs(v)) * 1e3 == pytest.approx(210, rel=0.10)
    assert np.max(np.abs(a)) == pytest.approx(3.8, rel=0.12)
    f, s = signal.welch(p, fs=1000, nperseg=20000)
    strongest = f[np.argsort(s)[::-1]]
    top = []
    for fp in strongest:
        if all(abs(fp - q) > 0.2 for q in top):
            top.append(fp)
        if len(top) == 3:
            break
    assert sorted(round(x / 1.2667) for x in top) == [1, 2, 4]


def test_position_shapes_scalar_and_vector() -> None:
    for name in ("fixed-a2-top", "mitral-1d"):
        src = make_scenario(name).source
        d = src.dim
        assert src.position(0.3).shape == (d,)
        assert src.position(np.array([0.1, 0.2, 0.3])).shape == (3, d)
        assert np.all(np.isfinite(src.position(np.array([-10.0, 1e4]))))  # any time
        vec = src.position(np.linspace(0, 5, 11))
        one = np.array([src.position(float(x)) for x in np.linspace(0, 5, 11)])
        np.testing.assert_allclose(vec, one, rtol=0, atol=1e-15)


def test_positions_are_metres_and_continuous() -> None:
    src = make_scenario("varying-a1-top").source
    t = np.arange(30, 130, 1 / 2000)  # the climb, the top and the first steps down
    p = src.position(t)
    assert np.max(np.abs(p)) < 0.02  # centimetres, not millimetres
    step = np.max(np.abs(np.diff(p, axis=0)))
    assert step < 2e-4  # no jumps: < 0.2 mm per 0.5 ms tick, even across rate steps


def test_whole_run_evaluation_is_fast() -> None:
    src = make_scenario("fixed-a2-top").source
    t = np.arange(120_000) / 2000.0
    src.position(t[:100])
    start = time.perf_counter()
    p = src.position(t)
    elapsed = time.perf_counter() - start
    assert p.shape == (120_000, 3)
    assert elapsed < 1.0, f"{elapsed:.2f} s for 120 000 samples"


def test_content_above_26_hz_is_small() -> None:
    """Tuna §III-B: components up to 26 Hz approximate the motion within 140 µm RMS."""
    sc = make_scenario("fixed-a2-top", duration=60.0)
    t = np.arange(0, 60, 1 / 1000)
    p = sc.source.position(t)
    spec = np.fft.rfft(p - p.mean(axis=0), axis=0)
    f = np.fft.rfftfreq(t.size, 1e-3)
    high = np.fft.irfft(np.where((f > 26)[:, None], spec, 0), t.size, axis=0)
    err = np.sqrt(np.mean(np.sum(high ** 2, axis=1)))
    assert 1e-7 < err < 140e-6
    mid = np.fft.irfft(np.where(((f > 8) & (f <= 26))[:, None], spec, 0), t.size, axis=0)
    assert np.sqrt(np.mean(np.sum(mid ** 2, axis=1))) > 20e-6  # broad band, not a pure sine


@pytest.mark.slow
def test_seeds_reproduce_and_differ() -> None:
    t = np.linspace(0, 30, 3001)
    a = make_scenario("fixed-a2-top", np.random.default_rng(7)).source.position(t)
    b = make_scenario("fixed-a2-top", np.random.default_rng(7)).source.position(t)
    c = make_scenario("fixed-a2-top", np.random.default_rng(8)).source.position(t)
    d = make_scenario("fixed-a2-top").source.position(t)
    e = make_scenario("fixed-a2-top").source.position(t)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(d, e)
    assert np.max(np.abs(a - c)) > 1e-4
    assert peak_to_peak(c) > 0


def test_calibration_holds_for_other_seeds() -> None:
    sc = make_scenario("varying-a3-top", np.random.default_rng(123))
    _, p = _record(sc)
    assert peak_to_peak(p) * 1e3 == pytest.approx(7.43, rel=0.02)


def test_beat_to_beat_variability() -> None:
    """Morphology varies a little from beat to beat; no variability → exactly periodic."""
    t = np.arange(0, 0.6, 1e-3)
    src = make_scenario("fixed-a2-top", breathing=False, coupling=0.0,
                        variability="clean").source
    beats = [src.position(t + k * 0.6) for k in range(5)]
    diff = max(np.max(np.abs(b - beats[0])) for b in beats[1:])
    assert 1e-5 < diff < 1.5e-3
    flat = make_scenario("fixed-a2-top", breathing=False, coupling=0.0,
                         beat_gain_std=0.0, variability="clean").source
    np.testing.assert_allclose(flat.position(t), flat.position(t + 3 * 0.6), atol=1e-12)


def test_overrides() -> None:
    sc = make_scenario("fixed-a2-top", duration=12.0, sensor_rate=404.0, heart_rate=1.2,
                       variability="clean")
    assert sc.duration == 12.0 and sc.sensor_rate == 404.0
    assert sc.source.phase.rate(np.array([3.0]))[0] == pytest.approx(1.2)
    assert SPECS["fixed-a2-top"].peak_to_peak == pytest.approx(8.39e-3)
    with pytest.raises(ValueError):
        make_scenario("fixed-a2-top", duration=-1.0)
