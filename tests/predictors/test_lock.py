"""Heart-rate lock: the EKF on the 3-D replicas with breathing, WFLC through ±10 bpm steps."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from rhmpc.predictors import make_predictor


def _sonomicrometry(name: str, seconds: float, **overrides):
    sim_heart = pytest.importorskip("rhmpc.sim.heart")
    sim_sensors = pytest.importorskip("rhmpc.sim.sensors")
    scn = sim_heart.make_scenario(
        name, rng=np.random.default_rng(4), duration=seconds + 1, **overrides
    )
    sensor = sim_sensors.sonomicrometry(
        sim_sensors.SonomicrometrySettings(rate=1 / 0.0075), dim=scn.dim
    )
    stream = sensor.measure(scn.source, seconds, np.random.default_rng(5))
    return scn, stream


def _lock_scores(name: str, scenario: str, params: str | None = None,
                 **overrides) -> tuple[float, int, float]:
    """(p95 |ω̂ − ω| [bpm] from 15 s = 10 s initialisation + 5 s, clamp count, 3-step RMS
    error / hold's) of predictor ``name`` (parameter set ``params``) on 30 s of the scenario's
    sonomicrometer stream."""
    scn, st = _sonomicrometry(scenario, 30.0, **overrides)
    p95, counts, ratio = _scores(name, scn, st, 0.0075, params=params)
    return p95, counts["omega_clamped"], ratio


def _bench_stream(scenario: str, seed: int, seconds: float = 30.0, **physics):
    """The stream of ``benchmarks/predictor_streams.py``: scenario and sensor seed ``seed``, every
    second sample of the 257 Hz sonomicrometer (Δt = 7.8 ms); ``physics``: sensor settings."""
    sim_scenarios = pytest.importorskip("rhmpc.sim.heart.scenarios")
    sim_sensors = pytest.importorskip("rhmpc.sim.sensors")
    scn = sim_scenarios.make_scenario(scenario, np.random.default_rng(seed), duration=seconds)
    sensor = sim_sensors.sensor_from_name("sonomicrometry", dim=int(scn.source.dim), **physics)
    st = sensor.measure(scn.source, seconds, np.random.default_rng(seed))
    return scn, SimpleNamespace(t=st.t[::2], z=st.z[::2])


def _scores(name: str, scn, st, dt: float, since: float = 15.0,
            params: str | None = None) -> tuple[float, dict, float]:
    """(p95 |ω̂ − ω| [bpm] from ``since`` [s], the predictor's counts, 3-step RMS error / hold's
    from then on)."""
    kw = {} if params is None else {"params": params}
    p, hold = make_predictor(name, dt, **kw), make_predictor("hold", dt)
    hr_err, e_p, e_hold = [], [], []
    for k in range(len(st.t) - 3):
        p.update(st.z[k])
        hold.update(st.z[k])
        if st.t[k] >= since:
            hr_err.append(60.0 * abs(p.heart_rate_hz - float(scn.source.phase.rate(st.t[k]))))
            e_p.append(np.linalg.norm(p.predict(3)[2] - st.z[k + 3]))
            e_hold.append(np.linalg.norm(hold.predict(3)[2] - st.z[k + 3]))
    ratio = float(np.sqrt(np.mean(np.square(e_p))) / np.sqrt(np.mean(np.square(e_hold))))
    return float(np.percentile(hr_err, 95)), p.counts, ratio


_RR_SINE = {"rr": 60.0 / (100.0 + 8.0 * np.sin(np.arange(60) / 3.0))}


@pytest.mark.parametrize("params", ["adaptive", "tuna2013-hrv"])
@pytest.mark.parametrize(
    ("scenario", "overrides", "tolerance"),
    [
        ("fixed-a1-top", {}, 5.0),  # lost lock with Tuna's q_ω (ω̂ at the 0.5 Hz clamp)
        ("fixed-a2-top", {}, 6.0),  # all of its rate variability respiratory: ±8.5 bpm in 3 s
        ("varying-a3-top", {}, 5.0),
        ("varying-a3-side", {}, 5.0),  # lost lock with Tuna's q_ω
        ("fixed-a2-top", _RR_SINE, 5.0),
    ],
)
@pytest.mark.slow
def test_ekf_keeps_heart_rate_lock_in_3d_with_breathing(scenario, overrides, tolerance, params):
    """Measured (seeds 4/5, in the order above, the default sonomicrometer with its white
    range error), ``adaptive`` / ``tuna2013-hrv``: p95 |ω̂ − ω| 3.1 / 5.5 / 3.8 / 3.2 / 3.2 bpm
    and 3.2 / 5.5 / 4.0 / 3.3 / 3.2 bpm, no clamp, 3-step RMS 0.35 / 0.42 / 0.42 / 0.46 / 0.39
    and 0.54 / 0.47 / 0.47 / 0.56 / 0.44 × hold's (with Tuna's q_ω fixed-a1-top and
    varying-a3-side lose lock: p95 56 / 61 bpm). Asserted: the lock tolerance (5 bpm; 6 where
    the rate swings with each breath), 0.55 / 0.8 × hold.  (varying-a1-top, not asserted:
    p95 5.4.)"""
    p95, clamped, ratio = _lock_scores("ekf", scenario, params, **overrides)
    assert p95 < tolerance and not clamped
    assert ratio < (0.55 if params == "adaptive" else 0.8)


@pytest.mark.parametrize(("scenario", "seed"), [("fixed-a1-top", 7), ("varying-a1-top", 2)])
@pytest.mark.slow
def test_ekf_refits_after_losing_lock(scenario, seed):
    """The predictor-bench stream at seed 7 / 2, 30 s: ω̂ falls out of the 36–180 beats/min band
    of the FFT initialisation 3–4 s after the fit (to its 30 beats/min clamp) and the filter
    re-fits its last 10 s (``lock_refit``, at 14.4 / 12.6 s).  Measured (in the order above):
    one re-fit, no clamp, p95 |ω̂ − ω| 3.0 / 4.7 bpm, 3-step RMS 0.40 / 0.53 × hold's; without
    the re-fit ω̂ stays at the clamp (380 / 648 clamps, p95 68 / 72 bpm, 1.65 / 1.62 × hold's).
    Asserted: the 5 bpm lock tolerance, 0.7 × hold."""
    p95, counts, ratio = _scores("ekf", *_bench_stream(scenario, seed), 2 / 257,
                                 params="tuna2013-hrv")
    assert counts["lock_refit"] == 1 and not counts["omega_clamped"]
    assert p95 < 5.0 and ratio < 0.7


@pytest.mark.parametrize(("scenario", "seed"), [("varying-a3-side", 3), ("varying-a1-side", 2)])
@pytest.mark.slow
def test_ekf_refits_after_locking_on_half_the_heart_rate(scenario, seed, monkeypatch):
    """The predictor-bench stream at seed 3 / 2, 40 s: 4–5 s after the fit ω̂ settles near half
    the heart rate (41–52 beats/min, inside the FFT's band: no clamp) and its second harmonic
    outweighs the fundamental. Once the window is all new the filter re-fits (``lock_refit``).
    Measured p95 |ω̂ − ω| over the last 8 s: 2.4 / 3.4 bpm; without the rule 50.2 / 45.9.
    The streams are those without the white range error, on which these cases were found."""
    from rhmpc.predictors.ekf_fourier import FourierEKF

    stream = _bench_stream(scenario, seed, 40.0, range_noise=0.0)
    kw = {"since": 32.0, "params": "tuna2013-hrv"}
    p95, counts, _ = _scores("ekf", *stream, 2 / 257, **kw)
    assert counts["lock_refit"] >= 1 and not counts["omega_clamped"] and p95 < 5.0
    monkeypatch.setattr(FourierEKF, "_subharmonic", lambda self: False)
    assert _scores("ekf", *stream, 2 / 257, **kw)[0] > 20.0


@pytest.mark.slow
def test_ekf_refits_when_its_rate_leaves_the_band_around_the_fit():
    """``adaptive`` on the bench stream of fixed-a1-top at seed 7: the fit starts 13 bpm low
    (87 against 99 beats/min), and with R̂ at 3–20 mm ω̂ drifts down (to 47 beats/min within
    9 s without ``rate_band``).  Leaving [ω₀/1.5, 1.5 ω₀] it re-fits (at 14.7 s).  Measured from
    20 s: p95 |ω̂ − ω| 3.2 bpm, 3-step RMS 0.32 × hold's (``tuna2013-hrv``: 2.7 bpm, 0.41)."""
    stream = _bench_stream("fixed-a1-top", 7)
    p95, counts, ratio = _scores("ekf", *stream, 2 / 257, since=20.0)
    assert counts["lock_refit"] >= 1 and not counts["omega_clamped"]
    assert p95 < 5.0 and ratio < 0.5


@pytest.mark.parametrize("scenario", ["varying-a1-top", "varying-a3-top", "varying-a1-side"])
@pytest.mark.slow
def test_dual_ekf_keeps_heart_rate_lock_in_3d_with_breathing(scenario):
    """Richa's zero start lost lock on the first two (ω̂_c at its clamp); the third needs the
    innovation gate.  Measured (physical sonomicrometer, seeds 4/5): p95 |ω̂_c − ω| 3.9 / 3.4 /
    3.1 bpm, no clamp, no gate rejection, 3-step RMS 0.30 / 0.30 / 0.32 × hold's (with the flat
    25 mm² / 1 mm² priors on the fitted breathing and offset: 6.2 / 3.6 / 99.8 bpm,
    varying-a1-side clamped, 0.56 / 0.39 / 3.58 × hold's); asserted: the 5 bpm lock
    tolerance, 0.9 × hold."""
    p95, clamped, ratio = _lock_scores("dual-ekf", scenario)
    assert p95 < 5.0 and not clamped
    assert ratio < 0.9


def _mitdb_100():
    """MIT-BIH record 100, shipped with the package."""
    return "mitdb-100"


@pytest.mark.parametrize(
    "scenario",
    ["fixed-a1-top", "fixed-a2-top", "varying-a1-top", "varying-a3-top", "varying-a1-side",
     "varying-a3-side"],
)
@pytest.mark.slow
def test_dual_ekf_keeps_heart_rate_lock_driven_by_mitdb_100(scenario):
    """Record 100's annotated beat times (from its first beat) drive the heart, 30 s.

    Measured (seeds 4/5, in the order above): p95 |ω̂_c − ω| 3.8 / 2.6 / 3.4 / 3.1 / 2.9 /
    3.2 bpm, no clamp, 3-step RMS 0.39 / 0.43 / 0.39 / 0.38 / 0.40 / 0.43 × hold's.  With
    the flat 25 mm² / 1 mm² priors on the fitted breathing and offset
    (``p0_respiratory_from_fit=False``) all six lose lock: p95 75–84 bpm, 0–689 clamps,
    2.9–4.4 × hold's.  Asserted: the 5 bpm lock tolerance, 0.6 × hold."""
    p95, clamped, ratio = _lock_scores("dual-ekf", scenario, record=_mitdb_100())
    assert p95 < 5.0 and not clamped
    assert ratio < 0.6


@pytest.mark.parametrize("scenario", ["fixed-a2-top", "varying-a1-top", "varying-a1-side"])
@pytest.mark.slow
def test_dual_ekf_refits_after_losing_lock_on_a_premature_beat(scenario):
    """Record 100 from t = 1200 s: atrial premature beats at 4.5, 10.9 and 28.9 s of the stream.

    The one 0.9 s after the 10 s fit takes ω̂_c out of the heart-rate band; the filter re-fits
    its window (``lock_refit``).  Measured (seeds 4/5, in the order above): no clamp, 3-step
    RMS 0.54 / 0.49 / 0.52 × hold's; without the re-fit ω̂_c stays lost (70 / 68 / 96 clamps,
    3.3 / 3.5 / 3.3 × hold's).  |ω̂_c − ω| is not asserted: the premature beat at 28.9 s swings
    the interpolated true rate 69 → 107 → 53 beats/min within a second."""
    from rhmpc.sim.heart.rr import beat_times_from_annotations

    beats = beat_times_from_annotations(_mitdb_100())
    beats = beats[beats >= 1200.0]
    _, clamped, ratio = _lock_scores("dual-ekf", scenario, beat_times=beats - beats[0])
    assert not clamped
    assert ratio < 0.9


def _step_signal(base, delta, seconds=45.0, step_at=30.0, dt=1 / 28):
    t = np.arange(int(seconds / dt)) * dt
    f = np.where(t < step_at, base / 60, (base + delta) / 60)
    ph = 2 * np.pi * np.cumsum(f) * dt
    z = 5 * np.sin(ph) + 2 * np.sin(2 * ph + 1) + np.sin(3 * ph + 2)
    return t, z[:, None] + 1.3 * np.random.default_rng(0).standard_normal((t.size, 1))


@pytest.mark.parametrize("base", [60.0, 103.0])
@pytest.mark.parametrize("delta", [-10.0, 10.0])
@pytest.mark.slow
def test_wflc_follows_a_10_bpm_step_without_clamping(base, delta):
    """28 Hz, 1-D in mm, σ = 1.3 mm (Yuen's protocol).

    Measured (seed 0): mean ω̂ over 10–15 s after the step within 0.1–0.9 bpm of the new
    rate, 90th percentile of |ω̂ − ω| 4.0–6.7 bpm (the PLL's jitter at this SNR), never
    clamped.  Riviere's gradient update (``loop="gradient"``) runs to its clamp at
    60 → 70 bpm.
    """
    dt = 1 / 28
    t, z = _step_signal(base, delta)
    p = make_predictor("wflc", dt)
    hr = []
    for k, zk in enumerate(z):
        p.update(zk)
        if t[k] >= 40.0:
            hr.append(60 * p.heart_rate_hz)
    assert abs(np.mean(hr) - (base + delta)) < 2.0
    assert np.percentile(np.abs(np.asarray(hr) - (base + delta)), 90) < 10.0
    assert not p.counts["omega_clamped"]
    riviere = {"loop": "gradient", "breathing_harmonics": 0, "phase_gain": 0.0,
               "frequency_harmonics": 8, "mu_bias": 0.03}
    q = make_predictor("wflc", dt, **riviere)
    for zk in z:
        q.update(zk)
    if base == 60.0 and delta == 10.0:  # runs away to its clamp
        assert abs(60 * q.heart_rate_hz - (base + delta)) > 10.0


@pytest.mark.slow
def test_wflc_tracks_a_chirp():
    """Heart rate sweeping 80 → 120 bpm over 30 s (1.33 bpm/s), 3-D, 128 Hz, σ = 0.1 mm.

    A type-2 loop follows a frequency ramp with a constant phase lag and no frequency
    bias; measured: |ω̂ − ω| RMS 0.5 bpm, max 2.4 bpm after the first 5 s.
    """
    dt = 1 / 128
    t = np.arange(int(45 / dt)) * dt
    f = np.interp(t, [0, 10, 40, 45], [80, 80, 120, 120]) / 60
    ph = 2 * np.pi * np.cumsum(f) * dt
    amp = np.array([[4.0, 1.5, 0.7], [2.0, 1.0, 0.3], [3.0, 0.5, 0.2]])
    z = sum(amp[:, i] * np.sin((i + 1) * ph[:, None] + i) for i in range(3))
    z = z + 0.1 * np.random.default_rng(1).standard_normal(z.shape)
    p = make_predictor("wflc", dt)
    err = []
    for k, zk in enumerate(z):
        p.update(zk)
        if t[k] >= 15.0:
            err.append(60 * (p.heart_rate_hz - f[k]))
    err = np.abs(err)
    assert np.sqrt(np.mean(err**2)) < 2.0
    assert err.max() < 5.0
    assert not p.counts["omega_clamped"]


@pytest.mark.parametrize("f_hz", [0.9, 1.6, 2.4])
@pytest.mark.slow
def test_wflc_recovers_a_constant_frequency(f_hz):
    """A 3-harmonic 1-D signal at 128 Hz, σ = 0.1 mm: ω̂ within 0.5 bpm after 20 s."""
    dt = 1 / 128
    t = np.arange(int(30 / dt)) * dt
    ph = 2 * np.pi * f_hz * t
    z = 5 * np.sin(ph) + 2 * np.sin(2 * ph + 1) + np.sin(3 * ph + 2)
    z = z[:, None] + 0.1 * np.random.default_rng(2).standard_normal((t.size, 1))
    p = make_predictor("wflc", dt)
    hr = []
    for k, zk in enumerate(z):
        p.update(zk)
        if t[k] >= 20.0:
            hr.append(60 * p.heart_rate_hz)
    assert abs(np.mean(hr) - 60 * f_hz) < 0.5
