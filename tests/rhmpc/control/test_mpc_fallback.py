"""Never trust a failed solve: the library's fallbacks, back-off, non-finite inputs and torque
bounds on constructed cases, and the settings' checks. The expected torques are rebuilt apart
from the library: the plan is the exact QP solution of its tick (DAQP; levels 1 and 2 are
exact), the LQ input the QP data's unconstrained minimiser, the braking torque its formula."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.settings import MPCSettings
from rhmpc.experiment.tables import from_dict, to_dict
from rhmpc.robots import linearize, load_robot
from tests.rhmpc.control.library import daqp_solve, mpc_library, qp_vectors, unconstrained


@pytest.fixture(scope="module")
def lib(arm):
    return mpc_library(arm)


@pytest.fixture
def fresh(lib):
    lib.reset()
    return lib


def _moving_ref(arm, N, k0=0, amp=2e-3):
    t = (k0 + np.arange(1, N + 1))[:, None] * arm.Ts
    return arm.y0 + amp * np.sin(2 * np.pi * 1.66 * t + np.array([0.0, 1.0, 2.0]))


def _run(lib, arm, ticks, k0=0, x=None):
    x = np.zeros(arm.nx) if x is None else x
    for k in range(ticks):
        tau = lib.mpc_step(x, _moving_ref(arm, lib.N, k0 + k))
        x = arm.A @ x + arm.B @ tau
    return x


def test_contract_shapes_and_reset(arm, fresh):
    lib = fresh
    assert lib.N == 50 and lib.mpc.settings == MPCSettings()
    assert np.allclose(lib.mpc.u_max, 0.75 * arm.torque_limit)
    tau = lib.mpc_step(np.zeros(6), _moving_ref(arm, lib.N))
    assert tau.shape == (3,) and lib.stats.status == "solved" and lib.stats.source == "qp"
    # the first tick saturates the torques: level 2 of the screening cascade settles it
    assert lib.stats.level == 2 and lib.stats.box_iterations > 0 and lib.stats.boxed == 1
    assert np.array_equal(lib.u, tau)
    tau[:] = 99.0  # the returned torque is the caller's
    assert np.all(np.abs(lib.u) <= lib.mpc.u_max)
    lib.reset()
    assert lib.stats.ticks == 0
    with pytest.raises(ValueError, match="expects"):
        lib.mpc_step(np.zeros(5), _moving_ref(arm, lib.N))
    with pytest.raises(ValueError, match="expects"):
        lib.mpc_step(np.zeros(6), _moving_ref(arm, lib.N)[:10])


def test_injected_failures_take_the_shifted_plan_then_lq(arm, fresh):
    lib, mpc = fresh, fresh.mpc
    x = _run(lib, arm, 49)
    ref, u_prev = _moving_ref(arm, mpc.N, 49), lib.u
    plan, _ = daqp_solve(mpc, *qp_vectors(mpc, x, ref, u_prev))  # the last good solve's
    tau = lib.mpc_step(x, ref)
    assert lib.stats.level in (1, 2)  # exact: its plan is DAQP's
    x = arm.A @ x + arm.B @ tau
    planned = mpc.qp.inputs(plan)  # (N, nu) inputs of the last good solve
    n_plan = mpc.settings.plan_fallback_ticks
    lib.force_failures(n_plan + 2)
    for k in range(1, n_plan + 3):
        ref = _moving_ref(arm, mpc.N, 49 + k)
        u_prev = lib.u
        tau = lib.mpc_step(x, ref)
        assert lib.stats.status == "injected"
        if k <= n_plan:
            assert lib.stats.source == "plan"
            np.testing.assert_allclose(tau, np.clip(planned[k], -mpc.u_max, mpc.u_max),
                                       rtol=0, atol=1e-9 * mpc.u_max.max())
        else:
            assert lib.stats.source == "lq"
            lq = np.clip(unconstrained(mpc, x, ref, u_prev), -mpc.u_max, mpc.u_max)
            np.testing.assert_allclose(tau, lq, rtol=0, atol=1e-9 * mpc.u_max.max())
        x = arm.A @ x + arm.B @ tau
    assert lib.stats.failures == {"injected": n_plan + 2}
    assert lib.stats.fallbacks == {"plan": n_plan, "lq": 2, "brake": 0, "zero": 0}
    assert lib.stats.fallback_total == n_plan + 2
    lib.mpc_step(x, _moving_ref(arm, mpc.N, 60 + n_plan))  # back to normal afterwards
    assert lib.stats.status == "solved" and lib.stats.source == "qp"


def test_failure_without_a_plan_uses_the_clipped_lq_input(arm, fresh):
    fresh.force_failures(1)
    x = np.array([1e-3, -1e-3, 2e-3, 0.0, 0.0, 0.0])
    ref = _moving_ref(arm, fresh.N)
    tau = fresh.mpc_step(x, ref)
    assert fresh.stats.source == "lq"
    u_max = fresh.mpc.u_max
    np.testing.assert_allclose(tau, np.clip(unconstrained(fresh.mpc, x, ref, np.zeros(3)),
                                            -u_max, u_max), rtol=0, atol=1e-9 * u_max.max())


def _unsettled(arm, **settings):
    """A library whose level 3 cannot finish (one ADMM iteration, a 1e-12 tolerance) on a
    target beyond tight joint bounds, which levels 1 and 2 do not settle, and that target."""
    lo, hi = arm.q0 - np.radians(1.0), arm.q0 + np.radians(1.0)
    lib = mpc_library(arm, MPCSettings(joint_lower=tuple(lo), joint_upper=tuple(hi), max_iter=1,
                                       osqp_eps_abs=1e-12, **settings))
    return lib, np.tile(arm.y0 + np.array([0.0, 10e-3, 0.0]), (lib.N, 1))


def test_a_solve_that_does_not_finish_takes_the_fallback(arm):
    lib, ref = _unsettled(arm, backoff_max_ticks=0)  # a solve on every tick
    x = np.zeros(6)
    x[3:] = 0.05
    for _ in range(3):
        tau = lib.mpc_step(x, ref)
        assert lib.stats.level == 3 and lib.stats.status == "max_iter"
        assert lib.stats.source in ("lq", "brake", "plan")
        assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= lib.mpc.u_max)
    assert lib.stats.failures == {"max_iter": 3}


def test_consecutive_failures_back_off_exponentially_up_to_the_cap(arm):
    lib, ref = _unsettled(arm, backoff_max_ticks=3)
    statuses = []
    for _ in range(16):
        lib.mpc_step(np.zeros(6), ref)
        statuses.append("M" if lib.stats.status == "max_iter" else lib.stats.status[0])
    # solves after rests of 1, 3 and then the cap of 3 ticks (2² − 1 = 3 < 2³ − 1)
    assert "".join(statuses) == "MbMbbbMbbbMbbbMb"
    assert lib.stats.failures == {"max_iter": 5, "backoff": 11}
    assert lib.stats.fallback_total == 16


def test_a_solved_tick_ends_the_back_off(arm):
    lib, ref = _unsettled(arm)
    for _ in range(3):  # failure, rest 1, failure: the next 3 ticks rest
        lib.mpc_step(np.zeros(6), ref)
    assert lib.stats.status == "max_iter"
    tau = lib.mpc_step(np.zeros(6), np.tile(arm.y0, (lib.N, 1)))  # level 1 settles it
    assert lib.stats.status == "solved" and lib.stats.level == 1
    assert np.all(np.isfinite(tau))
    lib.mpc_step(np.zeros(6), ref)  # the rest was not over, but the streak is: one tick of rest
    assert lib.stats.status == "backoff"
    lib.mpc_step(np.zeros(6), ref)
    lib.mpc_step(np.zeros(6), ref)
    assert lib.stats.status == "backoff"  # the streak restarted at 1 after this failure


def test_a_capped_box_qp_takes_the_fallback(arm):
    lib = mpc_library(arm, MPCSettings(box_max_iter=2))
    ref = np.tile(arm.y0 + np.array([0.3, -0.3, 0.3]), (lib.N, 1))  # far out of reach
    tau = lib.mpc_step(np.zeros(6), ref)
    assert lib.stats.level == 2 and lib.stats.box_iterations == 2
    assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= lib.mpc.u_max)
    assert lib.stats.status == "box_max_iter" and lib.stats.iterations == 0


def test_braking_stops_the_joints_within_the_first_block(arm):
    """Moving fast towards a joint limit with no plan: the clipped LQ input (towards a target
    past the limit) would break the envelope, so the fallback brakes,
    τ = clip(−M0 q̇ / (n₁ Ts), ±u_max)."""
    lo, hi = arm.q0 - np.radians(2.0), arm.q0 + np.radians(2.0)
    lib = mpc_library(arm, MPCSettings(joint_lower=tuple(lo), joint_upper=tuple(hi)))
    x = np.concatenate([np.radians([1.9, 0.0, 0.0]), [2.0, 0.0, 0.0]])
    ref = np.tile(arm.y0 + np.array([0.0, 0.05, 0.0]), (lib.N, 1))
    lib.force_failures(1)
    tau = lib.mpc_step(x, ref)
    assert lib.stats.source == "brake"
    u_max, n1 = lib.mpc.u_max, lib.mpc.settings.block_lengths[0]
    expected = np.clip(-(arm.M0 @ x[3:]) / (n1 * arm.Ts), -u_max, u_max)
    np.testing.assert_allclose(tau, expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("bad", ["x_nan", "x_inf", "ref_nan", "ref_inf", "ref_neg_inf"])
def test_nonfinite_inputs_trigger_the_fallback_without_exception(arm, fresh, bad):
    lib = fresh
    x = _run(lib, arm, 20)
    ref = _moving_ref(arm, lib.N, 20)
    if bad.startswith("x"):
        x = x.copy()
        x[2] = np.nan if bad == "x_nan" else np.inf
    else:
        ref = ref.copy()
        ref[7, 1] = {"ref_nan": np.nan, "ref_inf": np.inf, "ref_neg_inf": -np.inf}[bad]
    tau = lib.mpc_step(x, ref)
    assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= lib.mpc.u_max)
    assert lib.stats.status == "nonfinite_input" and lib.stats.source == "plan"
    assert lib.stats.failures == {"nonfinite_input": 1}
    # Without a plan, non-finite inputs give zero torque (the LQ input needs finite inputs).
    lib.reset()
    tau = lib.mpc_step(x, ref)
    assert lib.stats.source == "zero" and np.all(tau == 0)
    # And the controller recovers on the next good tick.
    lib.mpc_step(np.zeros(6), _moving_ref(arm, lib.N))
    assert lib.stats.status == "solved"


@pytest.mark.parametrize(
    "kwargs",
    [
        {"tracking_weight": math.nan},
        {"effort_weight": math.inf},
        {"rate_weight": -1.0},
        {"position_scale": 0.0},
        {"point_weights": (1.0,) * 49},
        {"point_weights": (math.nan,) * 50},
        {"point_weights": (0.0,) * 50},
        {"blocks": (10, 10)},
        {"blocks": (0, 50)},
        {"horizon": 0},
        {"torque_margin": 1.0},
        {"torque_margin": -0.1},
        {"terminal": "lqr"},
        {"osqp_eps_abs": 0.0},
        {"max_iter": 0},
        {"osqp_rho": 0.0},
        {"joint_lower": (0.0, 0.0, 0.0)},
        {"joint_lower": (1.0,), "joint_upper": (0.0,)},
        {"plan_fallback_ticks": -1},
        {"box_max_iter": 0},
        {"offset_correction": 1},
    ],
)
def test_bad_settings_raise_value_error(kwargs):
    with pytest.raises(ValueError):
        MPCSettings(**kwargs)


def test_settings_that_do_not_fit_the_arm_raise_at_build_time(arm):
    with pytest.raises(ValueError, match="torque limits"):
        RecedingHorizonMPC(dataclasses.replace(arm, torque_limit=np.array([1.0, 0.0, 1.0])))
    with pytest.raises(ValueError, match="torque limits"):
        RecedingHorizonMPC(dataclasses.replace(arm, torque_limit=-np.ones(3)))
    with pytest.raises(ValueError, match="shape"):
        RecedingHorizonMPC(dataclasses.replace(arm, B=np.zeros((6, 2))))
    with pytest.raises(ValueError, match="non-finite"):
        bad_A = arm.A.copy()
        bad_A[0, 0] = np.nan
        RecedingHorizonMPC(dataclasses.replace(arm, A=bad_A))
    with pytest.raises(ValueError, match="joint bounds must have"):
        RecedingHorizonMPC(arm, MPCSettings(joint_lower=(-1.0,) * 2, joint_upper=(1.0,) * 2))
    with pytest.raises(ValueError, match="contain"):
        RecedingHorizonMPC(arm, MPCSettings(joint_lower=tuple(arm.q0 + 0.1),
                                            joint_upper=tuple(arm.q0 + 0.2)))
    with pytest.raises(ValueError, match="effort_weight"):
        RecedingHorizonMPC(arm, MPCSettings(terminal="dare", effort_weight=0.0))
    with pytest.raises(ValueError, match="positive definite"):
        RecedingHorizonMPC(arm, MPCSettings(blocks=None, effort_weight=0.0, rate_weight=0.0,
                                            point_weights=(0.0,) * 49 + (1.0,)))
    with pytest.raises(ValueError, match="MPCSettings"):
        RecedingHorizonMPC(arm, {"horizon": 50})


def test_settings_round_trip_through_a_dict():
    s = MPCSettings(point_weights=tuple(np.linspace(1, 0.5, 50)), osqp_rho=1.5)
    d = to_dict(s)
    assert isinstance(d["blocks"], list) and "joint_lower" not in d
    assert d["osqp_rho"] == 1.5
    assert from_dict(MPCSettings, d) == s
    with pytest.raises(ValueError, match="unknown"):
        from_dict(MPCSettings, {"horizon": 50, "rhoo": 1.0})


@pytest.mark.parametrize("robot", ["finger_edu", "ur5"])
@pytest.mark.slow
def test_other_robots_build_and_track(robot):
    arm = linearize(load_robot(robot))
    lib = mpc_library(arm)
    x = _run(lib, arm, 200)
    assert lib.stats.fallback_total == 0
    err = np.linalg.norm(arm.C @ x + arm.y0 - _moving_ref(arm, 1, 199)[0])
    assert err < 1e-4
