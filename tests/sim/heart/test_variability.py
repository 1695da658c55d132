"""Physiological variability (rhmpc.sim.heart.variability): switches, magnitudes, seeds."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rhmpc.sim.heart import SPECS, make_scenario
from rhmpc.sim.heart.variability import (
    LF_BAND,
    VariabilitySettings,
    ar1,
    band_limited_noise,
    breathing_phase,
)

T = np.array([0.0, 1.234, 17.5, 99.99])

#: position(T) of each named replica [m] with the default seed, stored from the quasi-periodic
#: model without any variability process: the clean setting must reproduce it.
BEFORE = {
    "fixed-a2-top": [0.00031705244677746, 0.00016597432367883, 0.0002895865882637,
                     0.00456919189600024, 0.00267087867734634, -0.00110705761796878,
                     -0.00110079532327428, -0.0025773952639075, -0.00375802694330637,
                     -0.00222136398792189, -0.00100284592023715, 0.00116661358171701],
    "fixed-a1-top": [0.00045340069517279, 0.00024918617220076, 0.0004288679160077,
                     0.00550083776730454, 0.0048739937528311, 0.00216438066722476,
                     -0.003261726230989, -0.00166619411850779, 0.00157283585597776,
                     -0.00263098290245552, -0.00211102353027664, 0.00119364575347652],
    "varying-a1-top": [0.0005126160014506, 0.00028051725538438, 0.0004889777201946,
                       0.00619885778837429, 0.00548107218440256, 0.00240014860655826,
                       -0.00368395651637351, -0.00185964584362461, 0.00182121128376184,
                       -0.00317469382778244, -0.00217975427802879, 0.00065936612410842],
    "varying-a3-top": [0.00028067360222173, 0.000167014476984, 0.00030198001274823,
                       0.00335377334590293, 0.00326017139234248, 0.00141181099561206,
                       -0.00200479488401192, -0.00108802055585017, 0.00114452159406921,
                       -0.00171638511409551, -0.00129702006732127, 0.00039445592379467],
    "varying-a1-side": [0.00048369292449273, 0.00019245910186166, 0.0004967828391344,
                        -0.00041567061635148, 0.00387492450149462, 0.0053897821108848,
                        -0.00168913180417417, -0.00087549524636049, -0.00093731237294034,
                        -0.00057351055762547, -0.00135919898596224, -0.00155427435726761],
    "varying-a3-side": [0.00028464428945833, 0.0001170835309844, 0.00029686211192625,
                        -0.00032542100464126, 0.00238391202946556, 0.00335816451498762,
                        -0.00094005114044125, -0.00058368266207606, -0.00064339528324607,
                        -0.00032727908607727, -0.00084502204020532, -0.00097679910323618],
    "mitral-1d": [0.00912340331534884, 0.00831524598159865, -0.00296999075173299,
                  0.00774317277135091],
}


@pytest.mark.parametrize("name", sorted(BEFORE))
@pytest.mark.slow
def test_clean_gives_back_the_periodic_replica(name: str) -> None:
    """All mechanisms off = the replica as it was (to the 17 printed digits, ~1e-19 m)."""
    p = make_scenario(name, variability="clean").source.position(T)
    np.testing.assert_allclose(p.ravel(), BEFORE[name], rtol=0, atol=1e-17)
    q = make_scenario(name, variability=VariabilitySettings.clean()).source.position(T)
    np.testing.assert_array_equal(p, q)


_ALONE = {
    "hrv": dict(hrv_cv=0.06),
    "gain correlation": dict(beat_gain_correlation=0.3),
    "timing": dict(beat_timing_std=0.01),
    "breath period": dict(breath_period_cv=0.2),
    "breath depth": dict(breath_depth_cv=0.3),
    "drift": dict(drift_std=0.01),
    "coupling follows breath": dict(coupling_follows_breath=True, breath_period_cv=0.2),
}


@pytest.mark.parametrize("part", sorted(_ALONE))
@pytest.mark.slow
def test_each_mechanism_switches_on_alone(part: str) -> None:
    """Each setting alone changes the motion; the statistics stay calibrated."""
    t = np.arange(0, 60, 0.01)
    base = make_scenario("fixed-a2-top", duration=60.0, variability="clean").source.position(t)
    settings = replace(VariabilitySettings.clean(), **_ALONE[part])
    assert not settings.is_clean
    p = make_scenario("fixed-a2-top", duration=60.0, variability=settings).source.position(t)
    assert np.max(np.abs(p - base)) > 2e-5, part  # > 20 µm somewhere in a minute


def test_defaults_are_not_clean_and_validated() -> None:
    assert not VariabilitySettings().is_clean
    assert VariabilitySettings.clean().is_clean
    with pytest.raises(ValueError, match="hrv_cv"):
        VariabilitySettings(hrv_cv=-0.1)
    with pytest.raises(ValueError, match="correlation"):
        VariabilitySettings(beat_gain_correlation=1.0)
    with pytest.raises(ValueError, match="band_powers"):
        VariabilitySettings(band_powers=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="variability"):
        make_scenario("fixed-a2-top", variability="noisy")


def test_heart_rate_variability_magnitude_and_mean() -> None:
    """std(f_h)/mean(f_h) ≈ hrv_cv (0.06, Task Force), mean rate kept (100 bpm); the HF part
    locked to the breathing phase (fixed-a2-top: all of it, ``hrv_band_powers``)."""
    sc = make_scenario("fixed-a2-top")
    t = np.arange(0, sc.duration, 0.05)
    rate = sc.source.phase.rate(t)
    assert 60 * rate.mean() == pytest.approx(100.0, rel=0.01)
    assert np.std(rate) / np.mean(rate) == pytest.approx(0.06, rel=0.15)
    # RSA: part of the rate modulation is locked to the breathing phase
    x = np.cos(2 * np.pi * sc.source.breath_phase(t))
    y = np.sin(2 * np.pi * sc.source.breath_phase(t))
    m = rate / rate.mean() - 1
    locked = np.hypot(np.mean(m * x), np.mean(m * y)) * 2  # amplitude of the locked cosine
    powers = SPECS["fixed-a2-top"].hrv_band_powers
    share = powers[2] / sum(powers)
    assert locked == pytest.approx(0.06 * np.sqrt(2 * share), rel=0.1)


@pytest.mark.parametrize("name", ["varying-a1-top", "varying-a3-side"])
def test_staircase_levels_kept_on_average(name: str) -> None:
    """The pacing profile (Tuna §III-B) is the mean rate: over the record within 2 %, per 11 s
    of a step within 10 % (the slow VLF+LF part, σ ≈ 0.06·√(2491/3466) ≈ 5 %, is not averaged
    out in 11 s)."""
    sc = make_scenario(name)
    clean = make_scenario(name, variability="clean")
    t = np.arange(0, sc.duration, 0.05)
    assert sc.source.phase.rate(t).mean() == pytest.approx(
        clean.source.phase.rate(t).mean(), rel=0.02)
    for start in (10.0, 40.0, 55.0, 70.0, 85.0, 100.0, 115.0):
        t = np.arange(start + 2, start + 13, 0.05)
        assert sc.source.phase.rate(t).mean() == pytest.approx(
            clean.source.phase.rate(t).mean(), rel=0.10)


def test_band_limited_noise_spectrum() -> None:
    x = band_limited_noise(np.random.default_rng(0), 4096, 4.0, LF_BAND)
    assert np.mean(x) == pytest.approx(0, abs=1e-12) and np.std(x) == pytest.approx(1.0)
    f = np.fft.rfftfreq(x.size, 0.25)
    power = np.abs(np.fft.rfft(x)) ** 2
    inside = (f >= LF_BAND[0]) & (f <= LF_BAND[1])
    assert power[inside].sum() / power.sum() > 0.95


def test_ar1_correlation_and_std() -> None:
    s = ar1(np.random.default_rng(1), 20000, 0.03, 0.3, dim=2)
    assert np.std(s, axis=0) == pytest.approx([0.03, 0.03], rel=0.05)
    lag1 = [np.corrcoef(s[:-1, d], s[1:, d])[0, 1] for d in range(2)]
    assert lag1 == pytest.approx([0.3, 0.3], abs=0.03)


def test_breathing_phase_period_variability() -> None:
    track = breathing_phase(np.random.default_rng(2), 1 / 6, 3000.0, 0.21)
    onsets = track.beat_times(0.0, 3000.0)
    periods = np.diff(onsets)
    assert periods.mean() == pytest.approx(6.0, rel=0.02)
    assert np.std(periods) / periods.mean() == pytest.approx(0.21, rel=0.1)


def test_variable_replica_seeds_reproduce_and_differ() -> None:
    t = np.linspace(0, 30, 3001)
    a = make_scenario("varying-a3-top", np.random.default_rng(7)).source.position(t)
    b = make_scenario("varying-a3-top", np.random.default_rng(7)).source.position(t)
    c = make_scenario("varying-a3-top", np.random.default_rng(8)).source.position(t)
    np.testing.assert_array_equal(a, b)
    assert np.max(np.abs(a - c)) > 1e-4


def test_mitral_1d_is_periodic_by_default() -> None:
    """Yuen's §III-D studies add their own perturbations to mitral-1d: clean by default."""
    t = np.linspace(0, 20, 501)
    a = make_scenario("mitral-1d").source.position(t)
    b = make_scenario("mitral-1d", variability="clean").source.position(t)
    np.testing.assert_array_equal(a, b)
    c = make_scenario("mitral-1d", variability=VariabilitySettings()).source.position(t)
    assert np.max(np.abs(a - c)) > 1e-4
