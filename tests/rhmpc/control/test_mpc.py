"""The MPC's QP is the intended one, and the controller's library solves it: LQ/Riccati and LQR
(DARE) agreement, exact-QP agreement (DAQP), the screening cascade's levels, feasibility over many
warm-started ticks. The library's MPC runs alone (``mpc_step``); the references are built apart
from it (:mod:`tests.rhmpc.control.library`)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from rhmpc.bench.ticks import heart_like_reference
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.settings import MPCSettings
from tests.rhmpc.control.library import (
    daqp_input,
    daqp_solve,
    mpc_library,
    offset,
    qp_vectors,
    unconstrained,
)

#: OSQP run to (near) machine accuracy, for comparisons at 1e-6.
TIGHT = {"max_iter": 100_000, "osqp_eps_abs": 1e-10}


def _y0_seen(arm, x):
    """y0 + d: the output the offset-corrected model starts from, d = p(q) − (C x + y0)."""
    return arm.y0 + offset(arm, x)


def _small_problem(arm, rng, N=50):
    """A state, reference and previous input for which no torque bound is active."""
    x = np.concatenate([1e-5 * rng.normal(size=3), 1e-4 * rng.normal(size=3)])
    t = np.arange(1, N + 1)[:, None] * arm.Ts
    ref = arm.y0 + 2e-5 * np.sin(2 * np.pi * 1.66 * t + rng.uniform(0, 6, size=3))
    u_prev = 0.01 * rng.normal(size=3)
    return x, ref, u_prev


def _weights(mpc):
    """Q_k (N, ny, ny), R, R_Δ of the controller's settings, rebuilt from their definitions."""
    s, u_max, N = mpc.settings, mpc.u_max, mpc.N
    w = np.ones(N) if s.point_weights is None else np.asarray(s.point_weights)
    Q = np.array([s.tracking_weight * wk / s.position_scale**2 * np.eye(mpc.ny) for wk in w])
    R = s.effort_weight * np.diag(1 / u_max**2)
    Rd = s.rate_weight * np.diag(1 / u_max**2)
    return Q, R, Rd


def riccati_first_input(arm, Q, R, Rd, x0, ref, u_prev, terminal=None, y0=None):
    """Finite-horizon LQ tracking by the backward Riccati recursion (independent of the MPC).

    Augmented state ξ_k = [x_k; u_{k−1}], ξ⁺ = Â ξ + B̂ u; stage cost uᵀRu + (u − Eξ)ᵀR_Δ(u − Eξ),
    output cost (Ĉξ_k + y0 − r_k)ᵀ Q_k (…) at k = 1..N, optional terminal (x_N − x_s)ᵀW(x_N − x_s).
    Value function V_k(ξ) = ξᵀ S ξ + 2 sᵀ ξ + const. ``y0`` replaces ``arm.y0`` (the offset).
    """
    y0 = arm.y0 if y0 is None else y0
    nx, nu = arm.nx, arm.nu
    N = len(ref)
    Ah = np.zeros((nx + nu, nx + nu))
    Ah[:nx, :nx] = arm.A
    Bh = np.vstack([arm.B, np.eye(nu)])
    Ch = np.hstack([arm.C, np.zeros((arm.ny, nu))])
    E = np.hstack([np.zeros((nu, nx)), np.eye(nu)])
    S = Ch.T @ Q[N - 1] @ Ch
    s = Ch.T @ Q[N - 1] @ (y0 - ref[N - 1])
    if terminal is not None:
        W, x_s = terminal
        Ex = np.hstack([np.eye(nx), np.zeros((nx, nu))])
        S = S + Ex.T @ W @ Ex
        s = s - Ex.T @ W @ x_s
    for k in range(N - 1, -1, -1):
        Hu = R + Rd + Bh.T @ S @ Bh
        G = Bh.T @ S @ Ah - Rd @ E
        g = Bh.T @ s
        if k == 0:
            xi0 = np.concatenate([x0, u_prev])
            return -np.linalg.solve(Hu, G @ xi0 + g)
        S = E.T @ Rd @ E + Ah.T @ S @ Ah - G.T @ np.linalg.solve(Hu, G)
        s = Ah.T @ s - G.T @ np.linalg.solve(Hu, g)
        S = S + Ch.T @ Q[k - 1] @ Ch
        s = s + Ch.T @ Q[k - 1] @ (y0 - ref[k - 1])
    raise AssertionError("unreachable")


def blocked_lstsq_first_input(arm, blocks, Q, R, Rd, x0, ref, u_prev, y0=None):
    """The blocked problem as a weighted least-squares fit, built by forward simulation."""
    y0 = arm.y0 if y0 is None else y0
    nu, N = arm.nu, len(ref)
    nz = nu * len(blocks)
    tick_block = np.repeat(np.arange(len(blocks)), blocks)

    def rollout(z, x, up):
        res = []
        for k in range(N):
            b = tick_block[k]
            u = z[b * nu:(b + 1) * nu]
            res += [scipy.linalg.sqrtm(R).real @ u, scipy.linalg.sqrtm(Rd).real @ (u - up)]
            x = arm.A @ x + arm.B @ u
            res.append(scipy.linalg.sqrtm(Q[k]).real @ (arm.C @ x + y0 - ref[k]))
            up = u
        return np.concatenate(res)

    r0 = rollout(np.zeros(nz), x0, u_prev)
    J = np.column_stack([rollout(e, np.zeros(arm.nx), np.zeros(nu)) - rollout(
        np.zeros(nz), np.zeros(arm.nx), np.zeros(nu)) for e in np.eye(nz)])
    z, *_ = np.linalg.lstsq(J, -r0, rcond=None)
    return z[:nu]


def _rel(a, b):
    return np.max(np.abs(a - b)) / np.max(np.abs(b))


@pytest.mark.parametrize("point_weights", [None, "ramp"])
@pytest.mark.slow
def test_unblocked_first_input_equals_backward_riccati(arm, point_weights):
    rng = np.random.default_rng(1)
    pw = None if point_weights is None else tuple(np.linspace(1.0, 0.2, 50))
    settings = MPCSettings(blocks=None, point_weights=pw, effort_weight=1e-3, rate_weight=0.05,
                           **TIGHT)
    lib = mpc_library(arm, settings)
    mpc = lib.mpc
    Q, R, Rd = _weights(mpc)
    for _ in range(3):
        x, ref, u_prev = _small_problem(arm, rng)
        u_lq = riccati_first_input(arm, Q, R, Rd, x, ref, u_prev, y0=_y0_seen(arm, x))
        assert np.all(np.abs(u_lq) < 0.5 * mpc.u_max)  # the bounds are inactive
        assert _rel(unconstrained(mpc, x, ref, u_prev), u_lq) < 1e-6  # the QP data
        lib.reset()
        lib.take_over(u_prev)
        u = lib.mpc_step(x, ref)
        assert lib.stats.status == "solved" and lib.stats.level == 1
        assert _rel(u, u_lq) < 1e-6  # the library's level 1


def test_blocked_first_input_equals_blocked_least_squares(arm):
    rng = np.random.default_rng(2)
    settings = MPCSettings()
    lib = mpc_library(arm, settings)
    mpc = lib.mpc
    Q, R, Rd = _weights(mpc)
    x, ref, u_prev = _small_problem(arm, rng)
    y0 = _y0_seen(arm, x)
    u_ls = blocked_lstsq_first_input(arm, settings.blocks, Q, R, Rd, x, ref, u_prev, y0=y0)
    assert _rel(unconstrained(mpc, x, ref, u_prev), u_ls) < 1e-6
    lib.take_over(u_prev)
    assert _rel(lib.mpc_step(x, ref), u_ls) < 1e-6
    # …and blocking really changes the problem: the unblocked solution differs.
    u_free = riccati_first_input(arm, Q, R, Rd, x, ref, u_prev, y0=y0)
    assert _rel(u_free, u_ls) > 1e-3


@pytest.mark.parametrize("displacement_deg", [2.0, 10.0])
def test_output_offset_is_the_forward_kinematics_residual(arm, displacement_deg):
    """At rest at a posture q ≠ q0 with the reference on the tip (r_k = p(q)), the corrected
    controller's optimum is exactly u = 0 (zero cost): the library's offset is the forward
    kinematics' residual; the uncorrected formulation moves the arm."""
    x = np.zeros(6)
    x[:3] = np.radians(displacement_deg) * np.array([1.0, -0.7, 0.5])
    d = offset(arm, x)
    assert np.linalg.norm(d) > 1e-4  # 0.1 mm or more: the linearisation's floor
    lib = mpc_library(arm)
    ref = np.tile(arm.y0 + arm.C @ x + d, (lib.N, 1))
    u = lib.mpc_step(x, ref)
    # |u| is rounding only: F p cancels terms of ~1e3 (absolute positions [m] times the gain);
    # measured 1e-11 of u_max, asserted at 1e-9.
    assert np.max(np.abs(u) / lib.mpc.u_max) <= 1e-9
    plain = RecedingHorizonMPC(arm, MPCSettings(offset_correction=False))
    u_lin = unconstrained(plain, x, ref, np.zeros(3))
    assert np.max(np.abs(u_lin) / plain.u_max) > 1e-3


def test_dare_terminal_weight_gives_the_lqr_action(arm):
    """With the DARE's terminal weight, no blocking and no rate weight, the first input is the
    infinite-horizon LQR's, u = −K (x − x_s), K from scipy's DARE solution."""
    settings = MPCSettings(blocks=None, terminal="dare", effort_weight=1e-2, rate_weight=0.0,
                           horizon=20, offset_correction=False, **TIGHT)
    lib = mpc_library(arm, settings)
    mpc = lib.mpc
    Q, R, _ = _weights(mpc)
    Qx = arm.C.T @ Q[-1] @ arm.C
    P = scipy.linalg.solve_discrete_are(arm.A, arm.B, Qx, R)
    K = np.linalg.solve(R + arm.B.T @ P @ arm.B, arm.B.T @ P @ arm.A)
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = np.concatenate([1e-5 * rng.normal(size=3), 1e-4 * rng.normal(size=3)])
        # Regulation to y0, and to a constant offset target r (x_s = [C_q⁻¹(r − y0); 0]).
        for target in (np.zeros(3), 1e-5 * rng.normal(size=3)):
            ref = np.tile(arm.y0 + target, (mpc.N, 1))
            x_s = np.concatenate([np.linalg.solve(arm.C[:, :3], target), np.zeros(3)])
            u_lqr = -K @ (x - x_s)
            assert np.all(np.abs(u_lqr) < mpc.u_max)
            assert _rel(unconstrained(mpc, x, ref, np.zeros(3)), u_lqr) < 1e-6
            lib.reset()
            assert _rel(lib.mpc_step(x, ref), u_lqr) < 1e-6
    # Without the terminal weight a short horizon gives a different action; with it, the same.
    x = np.array([1e-5, -1e-5, 1e-5, 0.0, 0.0, 0.0])
    for terminal, differs in (("none", True), ("dare", False)):
        short = RecedingHorizonMPC(arm, MPCSettings(
            blocks=None, effort_weight=1e-2, rate_weight=0.0, horizon=3, terminal=terminal,
            offset_correction=False))
        u3 = unconstrained(short, x, np.tile(arm.y0, (3, 1)), np.zeros(3))
        assert (_rel(u3, -K @ x) > 1e-2) == differs


def test_active_torque_bounds_agree_with_daqp(arm):
    """A 4-mm jump saturates the torque: levels 1–2 settle it exactly (DAQP's u0 to 1e-9 of
    τ_max); with OSQP run to machine accuracy the result is the same."""
    x, jump = np.zeros(arm.nx), np.array([3e-3, -2e-3, 2e-3])
    for settings in (MPCSettings(), MPCSettings(**TIGHT)):
        lib = mpc_library(arm, settings)
        ref = np.tile(arm.y0 + jump, (lib.N, 1))
        z_ex, _ = daqp_solve(lib.mpc, *qp_vectors(lib.mpc, x, ref))
        assert np.sum(np.abs(z_ex) >= 1 - 1e-9) >= 3, "the test needs active bounds"
        tau = lib.mpc_step(x, ref)
        assert lib.stats.status == "solved" and lib.stats.level in (2, 3)
        assert np.max(np.abs(tau - daqp_input(lib.mpc, x, ref)) / arm.torque_limit) <= 1e-6


def test_active_joint_bounds_agree_with_daqp(arm):
    lo = arm.q0 - np.radians(1.0)
    hi = arm.q0 + np.radians(1.0)
    lib = mpc_library(arm, MPCSettings(joint_lower=tuple(lo), joint_upper=tuple(hi), **TIGHT))
    mpc = lib.mpc
    assert mpc.qp.param_bounds
    # A target 10 mm away needs ≈3° of joint motion: the joint bounds must become active.
    x, ref = np.zeros(arm.nx), np.tile(arm.y0 + np.array([0.0, 10e-3, 0.0]), (mpc.N, 1))
    x[3:] = 0.05  # moving already
    q, lo, up = qp_vectors(mpc, x, ref)
    tau = lib.mpc_step(x, ref)
    assert lib.stats.status == "solved" and lib.stats.level == 3
    z_ex, _ = daqp_solve(mpc, q, lo, up)
    Az = mpc.qp.A @ z_ex
    nv = mpc.qp.nv
    assert np.any(np.isclose(Az[nv:], up[nv:], atol=1e-8) | np.isclose(Az[nv:], lo[nv:], atol=1e-8))
    assert np.max(z_ex[mpc.qp.nz:]) <= 1e-9  # the soft envelope holds as the hard one would
    assert np.max(np.abs(tau - z_ex[:3] * mpc.u_max)) <= 1e-6


@pytest.mark.slow
def test_ten_thousand_warm_started_ticks_stay_within_the_bounds(arm):
    """Default settings, closed loop on the linear model, heart-like reference with jumps: every
    torque within ±u_max, no fallback, the bounds reached (the plant is the linear model
    itself, so the output offset is off)."""
    lib = mpc_library(arm, MPCSettings(offset_correction=False))
    mpc, ticks = lib.mpc, 10_000
    traj = heart_like_reference(ticks + mpc.N + 1, arm.Ts, np.random.default_rng(5), arm.y0,
                                jump=2e-3, jump_every=1000)
    x = np.zeros(arm.nx)
    x[:3] = np.linalg.solve(arm.C[:, :3], traj[0] - arm.y0)
    saturated = 0
    for k in range(ticks):
        tau = lib.mpc_step(x, traj[k + 1:k + 1 + mpc.N])
        assert np.all(np.abs(tau) <= mpc.u_max), (k, tau)
        saturated += bool(np.any(np.abs(tau) >= mpc.u_max * (1 - 1e-6)))
        x = arm.A @ x + arm.B @ tau
    assert lib.stats.ticks == ticks
    assert lib.stats.fallback_total == 0, lib.stats.failures
    assert saturated > 0  # the jumps did drive the torque into its bounds


def test_exact_reference_tracking_on_the_linear_model(arm):
    """Heart-like motion (8 mm p-p, 1.66 Hz + 4 harmonics, 0.17 Hz breathing), exact future.
    The plant is the linear model: no output offset."""
    lib = mpc_library(arm, MPCSettings(offset_correction=False))
    mpc, ticks = lib.mpc, 4000
    traj = heart_like_reference(ticks + mpc.N + 1, arm.Ts, np.random.default_rng(0), arm.y0)
    x = np.zeros(arm.nx)
    x[:3] = np.linalg.solve(arm.C[:, :3], traj[0] - arm.y0)
    err, taus = [], []
    for k in range(ticks):
        tau = lib.mpc_step(x, traj[k + 1:k + 1 + mpc.N])
        x = arm.A @ x + arm.B @ tau
        err.append(np.linalg.norm(arm.C @ x + arm.y0 - traj[k + 1]))
        taus.append(tau)
    rms = np.sqrt(np.mean(np.square(err[200:])))
    assert rms < 1e-5  # well below 0.1 mm (it is ~0.1 µm)
    assert np.max(np.abs(taus[200:])) < 0.1 * mpc.u_max.min()


@pytest.mark.parametrize("joint_bounds", [False, True])
@pytest.mark.slow
def test_screening_is_exact_and_hands_binding_ticks_to_osqp(arm, joint_bounds):
    """Ticks settled by the screening cascade (level 1: unconstrained minimiser; level 2: the
    torque-box QP) return the exact QP solution (DAQP, to 1e-9 of τ_max); the others go to OSQP
    (level 3). A C edit that breaks a level's decision or its arithmetic fails here."""
    extra = {"joint_envelope": False, "max_iter": 100}
    if joint_bounds:
        extra = {"joint_lower": tuple(arm.q0 - np.radians(5.0)),
                 "joint_upper": tuple(arm.q0 + np.radians(5.0)), "max_iter": 100}
    lib = mpc_library(arm, MPCSettings(**extra))
    mpc, ticks = lib.mpc, 1500
    traj = heart_like_reference(ticks + mpc.N + 1, arm.Ts, np.random.default_rng(2), arm.y0,
                                jump=4e-3, jump_every=500)
    x, u_prev = np.zeros(arm.nx), np.zeros(arm.nu)
    screened_err, levels = [], [0, 0, 0, 0]
    for k in range(ticks):
        ref = traj[k + 1:k + 1 + mpc.N]
        u_exact = daqp_input(mpc, x, ref, u_prev)
        tau = lib.mpc_step(x, ref)
        level = lib.stats.level
        levels[level] += 1
        if level in (1, 2):
            assert lib.stats.iterations == 0
            screened_err.append(np.max(np.abs(tau - u_exact) / arm.torque_limit))
        else:
            assert level == 3 and lib.stats.iterations > 0
        x, u_prev = arm.A @ x + arm.B @ tau, tau
    assert levels[1] > ticks // 2 and levels[2] > 0 and levels[0] == 0
    assert lib.stats.screened == levels[1] and lib.stats.boxed == levels[2]
    assert max(screened_err) <= 1e-9
    assert lib.stats.fallback_total == 0


def test_a_state_that_is_not_finite_leaves_the_next_tick_alone(arm):
    """A tick at a state that is not finite takes the fallback without touching what the next
    tick computes: with finite inputs it solves as a fresh library does."""
    lib = mpc_library(arm)
    x, ref = np.zeros(arm.nx), np.tile(arm.y0, (lib.N, 1))
    lib.mpc_step(np.full(arm.nx, np.nan), ref)
    assert lib.stats.status == "nonfinite_input" and lib.stats.source == "zero"
    lib.reset()
    first = lib.mpc_step(x, ref)
    lib.reset()
    np.testing.assert_array_equal(lib.mpc_step(x, ref), first)
    assert lib.stats.fallback_total == 0
