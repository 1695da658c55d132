"""Never trust a failed solve: fallbacks, non-finite inputs, torque bounds, bad settings."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import osqp
import pytest

from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.settings import MPCSettings
from rhmpc.experiment.tables import from_dict, to_dict
from rhmpc.robots import linearize, load_robot
from tests.rhmpc.control.exact import EveryTick, exact_mpc, qp_vectors, unconstrained

TIME_LIMIT = int(osqp.SolverStatus.OSQP_TIME_LIMIT_REACHED)


class WithoutLevel2(RecedingHorizonMPC):
    """The controller with level 2 skipped: a tick with a bound active goes to OSQP."""

    def _box_solved(self) -> bool:
        return False


@pytest.fixture
def mpc(arm):
    return RecedingHorizonMPC(arm)


def _moving_ref(arm, N, k0=0, amp=2e-3):
    t = (k0 + np.arange(1, N + 1))[:, None] * arm.Ts
    return arm.y0 + amp * np.sin(2 * np.pi * 1.66 * t + np.array([0.0, 1.0, 2.0]))


def _run(mpc, arm, ticks, k0=0, x=None):
    x = np.zeros(arm.nx) if x is None else x
    for k in range(ticks):
        tau = mpc.step(x, _moving_ref(arm, mpc.N, k0 + k))
        x = arm.A @ x + arm.B @ tau
    return x


def test_contract_shapes_and_reset(arm, mpc):
    assert mpc.N == 50 and mpc.settings == MPCSettings()
    assert np.allclose(mpc.u_max, 0.75 * arm.torque_limit)
    tau = mpc.step(np.zeros(6), _moving_ref(arm, mpc.N))
    assert tau.shape == (3,) and mpc.stats.status == "solved" and mpc.stats.source == "qp"
    # the first tick saturates the torques: level 2 of the screening cascade settles it
    assert mpc.stats.level == 2 and mpc.stats.box_iterations > 0 and mpc.stats.boxed == 1
    assert np.array_equal(mpc.u_prev, tau)
    mpc.reset()
    assert mpc.stats.ticks == 0 and np.all(mpc.u_prev == 0)
    with pytest.raises(ValueError, match=r"shape|expects"):
        mpc.step(np.zeros(5), _moving_ref(arm, mpc.N))
    with pytest.raises(ValueError, match="expects"):
        mpc.step(np.zeros(6), _moving_ref(arm, mpc.N)[:10])


def test_injected_failures_take_the_shifted_plan_then_lq(arm, mpc):
    x = _run(mpc, arm, 50)
    plan, _ = mpc.last_solution()
    planned = mpc.qp.inputs(plan)  # (N, nu) inputs of the last good solve
    n_plan = mpc.settings.plan_fallback_ticks
    mpc.force_failures(n_plan + 2)
    for k in range(1, n_plan + 3):
        ref = _moving_ref(arm, mpc.N, 50 + k)
        u_prev = mpc.u_prev
        tau = mpc.step(x, ref)
        assert mpc.stats.status == "injected"
        if k <= n_plan:
            assert mpc.stats.source == "plan"
            np.testing.assert_allclose(tau, np.clip(planned[k], -mpc.u_max, mpc.u_max))
        else:
            assert mpc.stats.source == "lq"
            lq = np.clip(unconstrained(mpc, x, ref, u_prev), -mpc.u_max, mpc.u_max)
            np.testing.assert_allclose(tau, lq)
        x = arm.A @ x + arm.B @ tau
    assert mpc.stats.failures == {"injected": n_plan + 2}
    assert mpc.stats.fallbacks == {"plan": n_plan, "lq": 2, "brake": 0, "zero": 0}
    assert mpc.stats.fallback_total == n_plan + 2
    # Back to normal afterwards.
    mpc.step(x, _moving_ref(arm, mpc.N, 60 + n_plan))
    assert mpc.stats.status == "solved" and mpc.stats.source == "qp"


def test_failure_without_a_plan_uses_the_clipped_lq_input(arm, mpc):
    mpc.force_failures(1, reason="injected")
    x = np.array([1e-3, -1e-3, 2e-3, 0.0, 0.0, 0.0])
    ref = _moving_ref(arm, mpc.N)
    tau = mpc.step(x, ref)
    assert mpc.stats.source == "lq"
    np.testing.assert_allclose(
        tau, np.clip(unconstrained(mpc, x, ref, np.zeros(3)), -mpc.u_max, mpc.u_max)
    )


def test_real_solver_failure_max_iter_takes_the_fallback(arm):
    mpc = WithoutLevel2(arm, MPCSettings(max_iter=1))
    x = np.zeros(6)
    for k in range(5):
        tau = mpc.step(x, _moving_ref(arm, mpc.N, k, amp=5e-3))
        assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= mpc.u_max)
        x = arm.A @ x + arm.B @ tau
    assert mpc.stats.failures.get("max_iter", 0) + mpc.stats.failures.get(
        "solved_inaccurate", 0) >= 1
    assert mpc.stats.fallback_total >= 1


def _failing(arm, **settings):
    """An MPC whose level 3 always fails (OSQP's status replaced by "time_limit") on a
    torque-saturating target that level 2 does not settle."""
    mpc = WithoutLevel2(arm, MPCSettings(**settings))
    solve = mpc._solver.solve
    mpc._solver.solve = lambda: (TIME_LIMIT, *solve()[1:])
    return mpc, np.tile(arm.y0 + np.array([3e-3, 0.0, 0.0]), (mpc.N, 1))


def test_a_failing_solve_takes_the_fallback(arm):
    mpc, ref = _failing(arm, backoff_max_ticks=0)  # a solve on every tick
    for _ in range(3):
        tau = mpc.step(np.zeros(6), ref)
        assert mpc.stats.status == "time_limit" and mpc.stats.source == "lq"
        assert np.all(np.abs(tau) <= mpc.u_max)
    assert mpc.stats.failures == {"time_limit": 3}


def test_consecutive_failures_back_off_exponentially_up_to_the_cap(arm):
    mpc, ref = _failing(arm, backoff_max_ticks=3)
    statuses = []
    for _ in range(16):
        mpc.step(np.zeros(6), ref)
        statuses.append("T" if mpc.stats.status == "time_limit" else mpc.stats.status[0])
    # solves after rests of 1, 3 and then the cap of 3 ticks (2² − 1 = 3 < 2³ − 1)
    assert "".join(statuses) == "TbTbbbTbbbTbbbTb"
    assert mpc.stats.failures == {"time_limit": 5, "backoff": 11}
    assert mpc.stats.fallback_total == 16


def test_a_solved_tick_ends_the_back_off(arm):
    mpc, ref = _failing(arm)
    for _ in range(3):  # failure, rest 1, failure: the next 3 ticks rest
        mpc.step(np.zeros(6), ref)
    assert mpc.stats.status == "time_limit"
    tau = mpc.step(np.zeros(6), np.tile(arm.y0, (mpc.N, 1)))  # level 1 settles a resting tick
    assert mpc.stats.status == "solved" and mpc.stats.level == 1
    assert np.all(np.isfinite(tau))
    mpc.step(np.zeros(6), ref)  # the rest was not over, but the streak is: one tick of rest
    assert mpc.stats.status == "backoff"
    mpc.step(np.zeros(6), ref)
    mpc.step(np.zeros(6), ref)
    assert mpc.stats.status == "backoff"  # the streak restarted at 1 after this failure


def test_a_capped_box_qp_takes_the_fallback(arm):
    mpc = RecedingHorizonMPC(arm, MPCSettings(box_max_iter=2))
    ref = np.tile(arm.y0 + np.array([0.3, -0.3, 0.3]), (mpc.N, 1))  # far out of reach
    tau = mpc.step(np.zeros(6), ref)
    assert mpc.box.capped and mpc.stats.level == 2
    assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= mpc.u_max)
    assert mpc.stats.status == "box_max_iter" and mpc.stats.iterations == 0


@pytest.mark.parametrize("bad", ["x_nan", "x_inf", "ref_nan", "ref_inf", "ref_neg_inf"])
@pytest.mark.slow
def test_nonfinite_inputs_trigger_the_fallback_without_exception(arm, mpc, bad):
    x = _run(mpc, arm, 20)
    ref = _moving_ref(arm, mpc.N, 20)
    if bad.startswith("x"):
        x = x.copy()
        x[2] = np.nan if bad == "x_nan" else np.inf
    else:
        ref = ref.copy()
        ref[7, 1] = {"ref_nan": np.nan, "ref_inf": np.inf, "ref_neg_inf": -np.inf}[bad]
    tau = mpc.step(x, ref)
    assert np.all(np.isfinite(tau)) and np.all(np.abs(tau) <= mpc.u_max)
    assert mpc.stats.status == "nonfinite_input" and mpc.stats.source == "plan"
    assert mpc.stats.failures == {"nonfinite_input": 1}
    # Without a plan, non-finite inputs give zero torque (the LQ input needs finite inputs).
    mpc.reset()
    tau = mpc.step(x, ref)
    assert mpc.stats.source == "zero" and np.all(tau == 0)
    # And the controller recovers on the next good tick.
    mpc.step(np.zeros(6), _moving_ref(arm, mpc.N))
    assert mpc.stats.status == "solved"


def _planned_then(mpc, arm, monkeypatch, fake):
    """Run 30 ticks, then make the solver do ``fake`` once; return (τ, the planned τ_1)."""
    x = _run(mpc, arm, 30)
    plan, _ = mpc.last_solution()
    planned = np.clip(mpc.qp.inputs(plan)[1], -mpc.u_max, mpc.u_max)
    monkeypatch.setattr(mpc._solver, "solve", fake)
    return mpc.step(x, _moving_ref(arm, mpc.N, 30)), planned


def _raise():
    raise RuntimeError("solver crashed")


@pytest.mark.parametrize("solver", ["daqp", "osqp"])
@pytest.mark.parametrize("fault, reason", [
    ("exception", "solver_error"),
    ("nan_solution", "nonfinite_solution"),
    ("infeasible", "primal_infeasible"),
])
@pytest.mark.slow
def test_injected_solver_faults_apply_the_shifted_plan(arm, monkeypatch, solver, fault, reason):
    # level 3 on every tick, OSQP with 100 iterations (not the real-time bound) or DAQP: only
    # the faults fail
    mpc = EveryTick(arm, MPCSettings(max_iter=100))
    if solver == "daqp":
        mpc._solver = exact_mpc(arm)._solver
    nv = mpc.qp.nv
    fakes = {
        "exception": _raise,
        "nan_solution": lambda: (1, 5, np.full(nv, np.nan)),
        "infeasible": lambda: (int(osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE), 5, np.zeros(nv)),
    }
    tau, planned = _planned_then(mpc, arm, monkeypatch, fakes[fault])
    assert mpc.stats.status == reason and mpc.stats.source == "plan"
    assert mpc.stats.failures == {reason: 1}
    np.testing.assert_array_equal(tau, planned)


def test_unclipped_solutions_are_feasible_and_fallbacks_are_the_documented_torques(arm, mpc):
    """Random states and references (some non-finite, some forced failures): a solved tick's
    raw solution (before the clip) satisfies the torque bounds to OSQP's primal tolerance
    eps_abs = 1e-3 (normalised inputs); a fallback
    tick returns exactly its documented torque."""
    rng = np.random.default_rng(7)
    sources = set()
    for i in range(300):
        scale = 10.0 ** rng.uniform(-6, -2)
        x = scale * rng.normal(size=6)
        ref = arm.y0 + scale * rng.normal(size=(mpc.N, 3))
        if i % 17 == 0:
            ref[rng.integers(mpc.N), rng.integers(3)] = np.nan
        if i % 29 == 0:
            mpc.force_failures(1)
        plan = None if mpc._plan is None else mpc._plan.copy()
        age = mpc._plan_age
        tau = mpc.step(x, ref)
        src = mpc.stats.source
        sources.add(src)
        if src == "qp":
            z, _ = mpc.last_solution()
            assert np.max(np.abs(z[:mpc.qp.nz])) <= 1 + 1e-3, (i, z[:3])
            np.testing.assert_array_equal(tau, np.clip(z[:3] * mpc.u_max, -mpc.u_max, mpc.u_max))
        elif src == "plan":
            k = min(age + 1, mpc.N - 1)
            b = mpc.qp.block_of_tick[k]
            np.testing.assert_array_equal(tau, np.clip(plan[b * 3:(b + 1) * 3] * mpc.u_max,
                                                       -mpc.u_max, mpc.u_max))
        elif src == "zero":
            assert np.all(tau == 0)
    assert mpc.stats.ticks == 300 and {"qp", "plan"} <= sources


@pytest.mark.slow
def test_osqp_on_every_tick_agrees_with_the_exact_solution_and_its_warm_start_pays(arm):
    """120 ticks of level 3 on the linear model, 5 mm sine, 100 iterations: u0 within 1 % of
    τ_max of DAQP's, in fewer iterations than from a cold start (v = 0 every tick)."""
    import daqp

    runs = {}
    for cold in (False, True):
        mpc = EveryTick(arm, MPCSettings(offset_correction=False, max_iter=100))
        qp, x, iters, errs = mpc.qp, np.zeros(6), [], []
        for k in range(120):
            ref = _moving_ref(arm, mpc.N, k, amp=5e-3)
            q, lo, up = qp_vectors(mpc, x, ref)
            if cold:
                mpc._ws_x, mpc._ws_y, mpc._ws_pending = np.zeros(qp.nv), mpc._y_zero, False
            tau = mpc.step(x, ref)
            z_ex, *_ = daqp.solve(qp.P, q, qp.A[qp.nv:], np.minimum(up, 1e30),
                                  np.maximum(lo, -1e30))
            if mpc.stats.source == "qp":
                errs.append(np.max(np.abs(tau - z_ex[:3] * mpc.u_max) / arm.torque_limit))
            iters.append(mpc.stats.iterations)
            x = arm.A @ x + arm.B @ tau
        assert mpc.stats.fallback_total <= 2, mpc.stats.failures  # a cold 5 mm first tick
        assert len(errs) >= 118 and max(errs) <= 0.01
        runs[cold] = float(np.mean(iters))
    assert runs[False] < runs[True] - 3.0


def test_returned_torque_is_not_aliased(arm, mpc):
    tau = mpc.step(np.zeros(6), _moving_ref(arm, mpc.N))
    tau[:] = 99.0
    assert np.all(np.abs(mpc.u_prev) <= mpc.u_max)


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
    mpc = RecedingHorizonMPC(arm)
    x = _run(mpc, arm, 200)
    assert mpc.stats.fallback_total == 0
    err = np.linalg.norm(arm.C @ x + arm.y0 - _moving_ref(arm, 1, 199)[0])
    assert err < 1e-4
