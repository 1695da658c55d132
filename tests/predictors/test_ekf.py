"""Fourier-series EKFs: parameter recovery, consistency (NIS), units."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from rhmpc.predictors import make_predictor
from rhmpc.predictors.ekf_fourier import wrap_phase
from tests.predictors.helpers import HarmonicSource, forecast_errors, run


@pytest.mark.parametrize("d", [1, 3])
def test_ekf_recovers_heart_rate_and_amplitudes(d):
    dt, f = 1 / 28, 1.1
    src = HarmonicSource(f_hz=f)
    src.amp, src.phase, src.offset = src.amp[:d], src.phase[:d], src.offset[:d]
    t = np.arange(int(30 / dt)) * dt
    rng = np.random.default_rng(5)
    z = src.position(t) + 0.05e-3 * rng.standard_normal((t.size, d))
    p = make_predictor("ekf", dt, params="yuen2008", sigma_r=0.05e-3)
    omegas, amps = [], []
    for k, zk in enumerate(z):
        p.update(zk)
        if t[k] > 20:
            omegas.append(p.omega)
            amps.append(p.amplitudes[:, :3])
    assert p.ready and not p.counts["ekf_reinit"]
    assert abs(np.mean(omegas) / (2 * np.pi * f) - 1) < 0.005
    np.testing.assert_allclose(np.mean(amps, axis=0), src.amp, rtol=0.02, atol=0.02 * src.amp.max())
    np.testing.assert_allclose(p.offsets, src.offset, atol=0.1e-3)


@pytest.mark.slow
def test_ekf_nis_within_chi2_bounds_on_its_own_model():
    dt, m, d = 1 / 28, 3, 1
    p = make_predictor(
        "ekf",
        dt,
        params="yuen2008",
        harmonics=m,
        sigma_r=0.5e-3,
        q=1e-4 * 1e-6,
        q_phase=1e-5,
        q_omega=1e-4,
        q_rate_hz=None,
        dim=d,
        unit=1.0,
    )
    rng = np.random.default_rng(6)
    x = np.zeros(p.nx)
    x[p.ic] = 1e-3
    x[p.ir.ravel()] = [4e-3, 1.5e-3, 0.7e-3]
    x[p.iw] = 2 * np.pi * 1.1
    x[p.ith.ravel()] = rng.uniform(-np.pi, np.pi, m)
    q, r = p._q, p._r
    P0 = np.diag(np.where(np.arange(p.nx) == p.iw, 1e-3, 1e-2 * np.maximum(q, 1e-10)))
    p.set_state(x + rng.multivariate_normal(np.zeros(p.nx), P0), P0)
    nis, K = [], 3000
    for _ in range(K):  # truth follows the filter's own model: x⁺ = F x + μ, z = h(x) + ν
        x[p.ith.ravel()] += np.arange(1, m + 1) * x[p.iw] * dt
        x += rng.normal(0.0, np.sqrt(q))
        wrap_phase(x[p.iw + 1 :])
        z = x[p.ic] + (x[p.ir] * np.sin(x[p.ith])).sum(axis=1) + rng.normal(0.0, np.sqrt(r), d)
        p.update(z)
        nis.append(p.nis)
    lo, hi = stats.chi2.ppf([0.005, 0.995], K * d) / K
    assert lo <= np.mean(nis) <= hi


def test_ekf_same_forecasts_in_metres_and_millimetres():
    dt = 1 / 28
    t = np.arange(int(15 / dt)) * dt
    z = HarmonicSource().position(t) + 1e-4 * np.random.default_rng(7).standard_normal((t.size, 3))
    f_m = run(make_predictor("ekf", dt, unit=1.0), z, 4)
    f_mm = run(make_predictor("ekf", dt, unit=1e-3), 1e3 * z, 4)
    np.testing.assert_allclose(f_mm, 1e3 * f_m, rtol=1e-7, atol=1e-7)


def test_yuen_process_noise_is_rescaled_to_the_predictor_rate():
    slow = make_predictor("ekf", 1 / 28, params="yuen2008", dim=1, unit=1.0)
    fast = make_predictor("ekf", 1 / 280, params="yuen2008", dim=1, unit=1.0)
    np.testing.assert_allclose(fast._q, slow._q / 10)


@pytest.mark.parametrize("name", ["dual-ekf", "wflc"])
def test_fourier_predictors_same_forecasts_in_metres_and_millimetres(name):
    dt = 1 / 28
    t = np.arange(int(15 / dt)) * dt
    z = HarmonicSource().position(t) + 1e-4 * np.random.default_rng(8).standard_normal((t.size, 3))
    f_m = run(make_predictor(name, dt, unit=1.0), z, 4)
    f_mm = run(make_predictor(name, dt, unit=1e-3), 1e3 * z, 4)
    np.testing.assert_allclose(f_mm, 1e3 * f_m, rtol=1e-6, atol=1e-6)


@pytest.mark.slow
def test_dual_ekf_tracks_breathing_plus_heartbeat():
    dt = 0.0075
    t = np.arange(int(40 / dt)) * dt
    src = HarmonicSource(f_hz=1.5, breathing=(0.2, [2e-3, 1e-3, 0.5e-3]))
    truth = src.position(t)
    z = truth + 0.1e-3 * np.random.default_rng(9).standard_normal(truth.shape)
    p = make_predictor("dual-ekf", dt, respiratory_hz=0.21, cardiac_hz=1.45)
    err = forecast_errors(run(p, z, 4), truth, 4)
    assert np.sqrt(np.mean(err[-int(10 / dt) :] ** 2)) < 0.15e-3
    assert abs(p.frequencies_hz[1] - 1.5) < 0.01


@pytest.mark.parametrize("d", [1, 2, 3, 5])
def test_spd_inverse_matches_numpy_and_rejects_indefinite(d):
    from rhmpc.predictors.ekf_fourier import spd_inverse

    A = np.random.default_rng(d).random((d, d))
    S = A @ A.T + np.eye(d)
    np.testing.assert_allclose(spd_inverse(S), np.linalg.inv(S), rtol=1e-12, atol=1e-14)
    bad = np.eye(d)
    bad[-1, -1] = -1.0
    assert spd_inverse(bad) is None


@pytest.mark.slow
def test_dual_ekf_refits_with_a_back_off_when_it_cannot_lock(monkeypatch):
    """A lock lost on every sample: re-fits spaced by 1, 2, 4 … beats, up to the window, not one
    per sample (each costs the window's FFT searches and fits)."""
    from rhmpc.predictors import make_predictor
    from rhmpc.predictors.ekf_dual_fourier import DualFourierEKF

    dt = 1 / 100
    t = np.arange(0.0, 40.0, dt)
    z = np.c_[3e-3 * np.sin(2 * np.pi * 1.2 * t), 2e-3 * np.cos(2 * np.pi * 1.2 * t),
              1e-3 * np.sin(2 * np.pi * 0.25 * t)]
    p = make_predictor("dual-ekf", dt)
    monkeypatch.setattr(DualFourierEKF, "_lost", lambda self: self._window.full)
    for row in z:
        p.update(row)
    refits, deferred = p.counts["lock_refit"], p.counts["refit_deferred"]
    window = len(p._window.samples)
    after = len(t) - window  # samples with a full window
    # at most one re-fit per window once the back-off has grown to it, plus its ramp-up
    assert refits <= after / window + np.log2(window) + 2, refits
    assert refits + deferred == after
    assert np.all(np.isfinite(p.predict(5)))
