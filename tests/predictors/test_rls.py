"""RLS predictors (one-step, generalized, AR) against independent references."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.predictors import make_predictor
from rhmpc.predictors.rls import RecursiveLeastSquares
from tests.predictors.helpers import HarmonicSource, forecast_errors, run


def _regression(z, N, lead=1):
    """Rows x_n = [z_{n−lead}; …; z_{n−lead−N+1}] and targets z_n."""
    X = np.array(
        [z[n - lead - N + 1 : n - lead + 1][::-1].reshape(-1) for n in range(N + lead - 1, len(z))]
    )
    Y = z[N + lead - 1 :]
    return X, Y


@pytest.mark.parametrize("correlated", [True, False])
def test_lambda_one_equals_batch_least_squares(correlated):
    rng = np.random.default_rng(0)
    d, N, T = 3, 4, 400
    z = rng.standard_normal((T, d)).cumsum(axis=0) * 0.1 + rng.standard_normal((T, d))
    delta = 1e-3
    p = make_predictor(
        "one-step",
        0.01,
        order=N,
        forgetting_factor=1.0,
        delta=delta,
        init="zeros",
        correlated=correlated,
        unit=1.0,
    )
    for zk in z:
        p.update(zk)
    X, Y = _regression(z, N)
    if correlated:  # ridge normal equations, exactly what RLS with P₀ = I/δ solves
        W = np.linalg.solve(X.T @ X + delta * np.eye(N * d), X.T @ Y).T
    else:
        W = np.empty((d, N))
        for a in range(d):
            Xa = X.reshape(len(X), N, d)[:, :, a]
            W[a] = np.linalg.solve(Xa.T @ Xa + delta * np.eye(N), Xa.T @ Y[:, a])
    assert np.abs(p.weights - W).max() <= 1e-8 * np.abs(W).max()
    # the prior is the only difference from ordinary least squares: as δ → 0 they agree
    q = make_predictor(
        "one-step", 0.01, order=N, forgetting_factor=1.0, delta=1e-7, init="zeros", unit=1.0
    )
    for zk in z:
        q.update(zk)
    W_ls = np.linalg.lstsq(X, Y, rcond=None)[0].T
    assert np.abs(q.weights - W_ls).max() <= 1e-6 * np.abs(W_ls).max()


def _var2(T, rng):
    A1 = np.array([[0.5, 0.2, 0.0], [-0.1, 0.4, 0.1], [0.0, 0.2, 0.3]])
    A2 = np.array([[-0.3, 0.0, 0.1], [0.1, -0.2, 0.0], [0.0, 0.1, -0.25]])
    z = np.zeros((T, 3))
    e = rng.standard_normal((T, 3)) * 1e-3
    for k in range(2, T):
        z[k] = A1 @ z[k - 1] + A2 @ z[k - 2] + e[k]
    return A1, A2, z


@pytest.mark.slow
def test_one_step_recovers_var2():
    A1, A2, z = _var2(20000, np.random.default_rng(1))
    p = make_predictor("one-step", 0.01, order=2, forgetting_factor=1.0, init="zeros")
    for zk in z:
        p.update(zk)
    np.testing.assert_allclose(p.weights, np.hstack([A1, A2]), atol=0.02)


@pytest.mark.slow
def test_generalized_recovers_var2_horizon_blocks():
    A1, A2, z = _var2(20000, np.random.default_rng(2))
    p = make_predictor("generalized", 0.01, order=2, points=2, forgetting_factor=1.0, init="zeros")
    for zk in z:
        p.update(zk)
    V = p.weights  # rows [ẑ_{n+1}; ẑ_{n+2}]
    np.testing.assert_allclose(V[:3], np.hstack([A1, A2]), atol=0.02)
    np.testing.assert_allclose(V[3:], np.hstack([A1 @ A1 + A2, A1 @ A2]), atol=0.03)


def test_one_step_matches_padasip_rls():
    pa = pytest.importorskip("padasip")
    rng = np.random.default_rng(3)
    N, lam, eps = 6, 0.99, 0.1
    z = np.sin(0.3 * np.arange(600)) + 0.3 * rng.standard_normal(600)
    ours = make_predictor(
        "one-step",
        0.01,
        order=N,
        forgetting_factor=lam,
        delta=eps,
        init="zeros",
        p_max_factor=1e12,
        unit=1.0,
    )
    ref = pa.filters.FilterRLS(N, mu=lam, eps=eps, w="zeros")
    for n, zn in enumerate(z):
        ours.update([zn])
        if (
            n >= N
        ):  # padasip: a-priori error e = d − wᵀx, R ← (R − R x xᵀ R/(μ + xᵀRx))/μ, w += R x e
            ref.adapt(zn, z[n - N : n][::-1].copy())
    np.testing.assert_allclose(ours.weights[0], ref.w, rtol=0, atol=1e-8 * np.abs(ref.w).max())


@pytest.mark.parametrize("name", ["one-step", "generalized"])
def test_noiseless_harmonics_25ms_forecast_below_1um(name):
    dt = 0.0075
    t = np.arange(int(40 / dt)) * dt
    truth = HarmonicSource().position(t)
    p = make_predictor(name, dt)
    fc = run(p, truth, steps=4)
    err = forecast_errors(fc, truth, 4)  # 30 ms ahead ≥ the 25 ms horizon
    assert err[-int(5 / dt) :].max() < 1e-6
    assert np.isfinite(fc).all()


@pytest.mark.parametrize("name", ["one-step", "generalized", "ar"])
@pytest.mark.slow
def test_same_forecasts_in_metres_and_millimetres(name):
    rng = np.random.default_rng(4)
    dt = 0.0075
    t = np.arange(1500) * dt
    z = HarmonicSource().position(t) + 1e-4 * rng.standard_normal((t.size, 3))
    p_m = make_predictor(name, dt)
    p_mm = make_predictor(name, dt, unit=1e-3)
    f_m, f_mm = run(p_m, z, 4), run(p_mm, z * 1e3, 4)
    np.testing.assert_allclose(f_mm[-200:], 1e3 * f_m[-200:], rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("shape", [{}, {"order": 3, "points": 6}])
def test_generalized_chains_beyond_its_points(shape):
    dt = 0.0075
    t = np.arange(3000) * dt
    src = HarmonicSource()
    p = make_predictor("generalized", dt, **shape)
    for zk in src.position(t):
        p.update(zk)
    f = p.predict(10)
    assert f.shape == (10, 3)
    if not shape:  # Tuna's N = 10 models the source; N = 3 < M = 6 need not
        np.testing.assert_allclose(f, src.position(t[-1] + dt * np.arange(1, 11)), atol=1e-6)
    # the chain itself: V applied to the newest N rows, its own forecasts pushed as observed
    V, N, M = p.weights, p.settings.order, p.settings.points
    rows, chained = list(p.line.buf[:N]), []  # newest first
    while len(chained) < 10:
        block = (V @ np.concatenate(rows[:N])).reshape(M, 3)
        chained += list(block)
        rows = list(block[::-1]) + rows
    assert p.counts["forecast_clamped"] == 0
    np.testing.assert_allclose(f, chained[:10], rtol=1e-12, atol=1e-15)


def test_rls_kernel_bounds_windup_and_counts_it():
    rls = RecursiveLeastSquares(1, 4, 1, forgetting_factor=0.9, delta=1.0, p_max_factor=10.0)
    x = np.array([[1.0, 0.0, 0.0, 0.0]])  # only one direction is excited
    for _ in range(200):
        rls.update(x, np.array([[2.0]]))
    assert np.diag(rls.covariance()).max() <= 10.0 + 1e-9
    assert rls.counts["rls_bound"] > 0
    np.testing.assert_allclose(rls.W[0, 0, 0], 2.0, rtol=1e-9)
