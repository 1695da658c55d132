"""Per-tick timing benchmark of the MPC, with two references measured in the same run.

The controller runs alone, in closed loop with its own linear model (x⁺ = A x + B τ, not timed),
on a moving heart-like reference with occasional reference jumps that saturate the torque
bounds (so that the QP has active constraints). Every tick measures, with
``time.perf_counter_ns``:

* the MPC tick of the controller's library (``rhmpc_mpc``: the screening cascade, OSQP only
  where levels 1 and 2 do not settle the tick), timed inside C;
* the same QP given to OSQP's own Python interface on *every* tick (:class:`EveryTick`),
  warm-started by OSQP, fed the same state and reference;
* the *gain tick* g (:class:`rhmpc.timing.yardstick.GainTick`): the unconstrained gain on
  p = [x; r; u_{−1}], u = K p + k₀ — the yardstick every timing is a multiple of — and the same
  mat-vec in plain NumPy (``K @ concatenate(...) + k0``), so that g reads as what it is;
* an *exact tick*: the same QP (same P, q, A, l, u) solved by the active-set solver DAQP,
  hot-started from its previous active set. Its u0 is the accuracy reference:
  ``u0_error = |u0_mpc − u0_exact| / τ_max`` per joint (τ_max = the robot's torque limit);
* with ``controller="c"``, the whole controller as ``rhmpc export`` writes it (the
  generalized predictor's refresh in C, the observer, the MPC and the cancellation) in a closed
  loop of its own on the same linear model and reference: a sensor samples the reference every
  ``downsample`` ticks (one tick late), the model is driven by the MPC torque, and every tick,
  refresh ticks included, is timed inside C (``clock_gettime(CLOCK_MONOTONIC)``) beside the
  gain tick on the C's own state and points: ``exported_tick_us`` and ``exported_tick_g``;
  ``c_tick_us``, the ticks without a refresh.
"""

from __future__ import annotations

import gc
import math
import platform
import time
from collections.abc import Callable
from importlib.metadata import version as _version

import numpy as np

from rhmpc.bench.exported import exported_ticks, percentiles
from rhmpc.control.controller import Controller
from rhmpc.control.export.generate import osqp_solver
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.observer import JointObserver
from rhmpc.control.reference import PredictedReference
from rhmpc.control.settings import MPCSettings
from rhmpc.experiment.tables import to_dict
from rhmpc.predictors.registry import make_predictor
from rhmpc.robots import linearize, load_robot
from rhmpc.robots.linearize import LinearArm
from rhmpc.sim.loop.metrics import warm_ns
from rhmpc.timing.yardstick import GainTick, numpy_gain_step

#: What :func:`run_bench` times: the MPC alone, or also the whole controller (``"c"``).
CONTROLLERS: tuple[str, ...] = ("python", "c")


def heart_like_reference(
    n: int,
    Ts: float,
    rng: np.random.Generator,
    center: np.ndarray,
    *,
    heart_pp: float = 8e-3,
    heart_rate: float = 1.66,
    harmonics: int = 4,
    breathing_pp: float = 4e-3,
    breathing_rate: float = 0.17,
    jump: float = 0.0,
    jump_every: int = 0,
) -> np.ndarray:
    """Synthetic point-of-interest positions p(k·Ts), shape (n, 3) [m].

    Per axis a, with random phases φ from ``rng``::

        p_a(t) = c_a + d_a · heart_pp · h_a(t) + breathing_a(t) + jumps_a(t)
        h_a(t) ∝ Σ_{i=1..harmonics+1} i^−1.2 cos(2π i f t + φ_{a,i}),  scaled to 1 peak-to-peak

    with d = (1, 0.6, 0.4), breathing (sinusoid at ``breathing_rate`` [Hz], ``breathing_pp`` [m]
    on x, half of it on z) and, if ``jump_every`` > 0 [ticks], a step of ``jump`` [m] in a random
    direction every ``jump_every`` ticks (alternating out and back).
    """
    t = np.arange(n) * Ts
    amps = 1.0 / np.arange(1, harmonics + 2) ** 1.2
    dirs = (1.0, 0.6, 0.4)
    out = np.empty((n, 3))
    for a in range(3):
        phases = rng.uniform(0.0, 2 * np.pi, harmonics + 1)
        s = sum(
            amps[i] * np.cos(2 * np.pi * (i + 1) * heart_rate * t + phases[i])
            for i in range(harmonics + 1)
        )
        out[:, a] = dirs[a] * heart_pp * s / (s.max() - s.min())
    breath = 0.5 * breathing_pp * np.sin(2 * np.pi * breathing_rate * t)
    out[:, 0] += breath
    out[:, 2] += 0.5 * breath
    if jump_every > 0 and jump > 0:
        offset = np.zeros(3)
        for i, k in enumerate(range(jump_every, n, jump_every)):
            if i % 2 == 0:
                d = rng.normal(size=3)
                offset = jump * d / np.linalg.norm(d)
                out[k:] += offset
            else:
                out[k:] -= offset
    return np.asarray(center, dtype=float) + out


class QPParameters:
    """p = [x; r_1..r_N; u_{−1}; d] in a preallocated buffer, d = p(q0 + x_q) − (C x + y0) by the
    robot's forward kinematics as in the controller, so that the references solve the QP the
    controller solves."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        qp, arm = mpc.qp, mpc.arm
        self.p = np.zeros(qp.npar)
        self._nx, self._nr, self._nu = qp.nx, qp.N * qp.ny, qp.nu
        self._d = self.p[self._nx + self._nr + self._nu :]
        self._arm = arm if mpc.settings.offset_correction else None

    def fill(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> bool:
        """Write p; False if it is not finite."""
        p, arm = self.p, self._arm
        p[: self._nx] = x
        p[self._nx : self._nx + self._nr] = ref.reshape(-1)
        p[self._nx + self._nr : self._nx + self._nr + self._nu] = u_prev
        if arm is not None:
            self._d[:] = arm.robot.ee_position(arm.q0 + x[: self._nu]) - (arm.C @ x + arm.y0)
        return math.isfinite(p.sum())


class EveryTick:
    """Reference 1: the tick's QP given to OSQP's own Python interface on every tick, with the
    controller's OSQP settings (:func:`rhmpc.control.export.generate.osqp_solver`), warm-started
    by OSQP: the clipped first input of its iterate after at most ``max_iter`` iterations
    (``solved`` tells whether it met its tolerance)."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        self._qp, self._params = mpc.qp, QPParameters(mpc)
        self._solver = osqp_solver(mpc.qp, mpc.settings)
        self.iterations, self.solved, self.solve_ns = 0, True, 0

    def __call__(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        qp = self._qp
        self._params.fill(x, ref, u_prev)
        p = self._params.p
        if qp.param_bounds:
            lower, upper = qp.bounds(p)
            self._solver.update(q=qp.q(p), l=lower, u=upper)
        else:
            self._solver.update(q=qp.q(p))
        t0 = time.perf_counter_ns()
        result = self._solver.solve(raise_error=False)
        self.solve_ns = time.perf_counter_ns() - t0
        self.iterations = result.info.iter
        self.solved = result.info.status_val == 1  # OSQP_SOLVED
        u = np.nan_to_num(result.x[: qp.nu]) * qp.u_max
        return np.clip(u, -qp.u_max, qp.u_max)


def bench_controller(arm: LinearArm, settings: MPCSettings) -> Controller:
    """The controller library of ``settings`` on ``arm`` for :meth:`Controller.mpc_step` (a
    generalized predictor's reference at 15 ticks, which the MPC alone does not read)."""
    predictor = make_predictor("generalized", 15 * arm.Ts, data_unit=1.0)
    reference = PredictedReference(predictor, arm.Ts, settings.horizon, 15)
    return Controller(RecedingHorizonMPC(arm, settings), reference,
                      JointObserver(arm, None), None, arm.torque_limit)


class ExactTick:
    """Reference 2: the same QP solved exactly by DAQP (active set, hot-started)."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        try:
            import daqp
        except ImportError:
            raise ValueError(
                "the exact reference needs the daqp package (an rhmpc dependency: pip install daqp)"
            ) from None
        qp = mpc.qp
        self._qp = qp
        self._params = QPParameters(mpc)
        self._f = np.empty(qp.nv)
        self._nu, self._nv = qp.nu, qp.nv
        self._lo = -qp.u_max
        self._model = daqp.Model()
        # The first nv rows of A are the identity (torque and slack bounds): DAQP takes them as
        # simple bounds, the envelope rows as its general constraints.
        self._A = np.ascontiguousarray(qp.A[qp.nv :])
        self._bu, self._bl = self._bounds(qp.l0, qp.u0)
        exitflag, _ = self._model.setup(qp.P, qp.f0.copy(), self._A, self._bu, self._bl)
        if exitflag < 0:
            raise ValueError(f"DAQP setup failed with exit flag {exitflag}")
        self.iterations = 0
        self.exitflag = 1
        self.zhat = np.zeros(qp.nz)

    @staticmethod
    def _bounds(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.minimum(upper, 1e30), np.maximum(lower, -1e30)  # DAQP's infinity

    def __call__(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        self._params.fill(x, ref, u_prev)
        p = self._params.p
        np.dot(self._qp.F, p, out=self._f)
        self._f += self._qp.f0
        if self._qp.param_bounds:
            lower, upper = self._qp.bounds(p)
            self._bu, self._bl = self._bounds(lower, upper)
            self._model.update(f=self._f, bupper=self._bu, blower=self._bl)
        else:
            self._model.update(f=self._f)
        z, _, exitflag, info = self._model.solve()
        self.exitflag, self.iterations, self.zhat = exitflag, info["iterations"], z[: self._qp.nz]
        u = z[: self._nu] * self._qp.u_max
        np.maximum(u, self._lo, out=u)
        return np.minimum(u, self._qp.u_max, out=u)


def _ratio(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    return {
        "p50": float(np.median(a) / np.median(b)),
        "p99": float(np.percentile(a, 99) / np.percentile(b, 99)),
    }


class _Ticks:
    """One run of the benchmark: the controllers it times and a column per measured figure."""

    COLUMNS = ("tick_ns", "every_ns", "gain_ns", "numpy_ns", "exact_ns", "solve_ns", "iters",
               "exact_iters", "u0_err", "every_err", "active", "screened", "level", "box_iters",
               "err")

    def __init__(self, controller: Controller, total: int) -> None:
        mpc = controller.mpc
        arm = mpc.arm
        self.controller, self.mpc, self.arm = controller, mpc, arm
        self.every = EveryTick(mpc)
        self.gain, self.exact = GainTick(mpc), ExactTick(mpc)
        self.numpy_gain = numpy_gain_step(self.gain._K, self.gain._k0)
        self.tau_max = np.asarray(arm.torque_limit, dtype=float)
        for name in self.COLUMNS:
            dtype = float if name.endswith("err") else bool if name in ("active", "screened") \
                else np.int64
            setattr(self, name, np.zeros(total, dtype=dtype))
        self.exact_failures = self.every_failures = 0

    def tick(self, k: int, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """Time every controller on tick ``k`` with state ``x`` and points ``ref``; returns τ."""
        c, every, exact, clock = self.controller, self.every, self.exact, time.perf_counter_ns
        u_prev, n_screened = c.u, c.stats.screened
        tau = c.mpc_step(x, ref)
        stats = c.stats
        self.gain_ns[k] = warm_ns(self.gain, x, ref, u_prev)
        self.numpy_ns[k] = warm_ns(self.numpy_gain, x, ref, u_prev)
        t2 = clock()
        u_exact = exact(x, ref, u_prev)
        t3 = clock()
        tau_every = every(x, ref, u_prev)  # the same QP as the controller's and DAQP's
        t4 = clock()
        self.tick_ns[k], self.exact_ns[k] = c.step_ns, t3 - t2
        self.every_ns[k], self.solve_ns[k] = t4 - t3, every.solve_ns
        self.screened[k] = stats.screened > n_screened
        self.level[k], self.box_iters[k] = stats.level, stats.box_iterations
        self.iters[k] = every.iterations
        self.every_failures += not every.solved
        self.exact_iters[k] = exact.iterations
        self.exact_failures += exact.exitflag < 0
        self.active[k] = bool(np.any(np.abs(exact.zhat) >= 1.0 - 1e-9))
        self.u0_err[k] = float(np.max(np.abs(tau - u_exact) / self.tau_max))
        self.every_err[k] = float(np.max(np.abs(tau_every - u_exact) / self.tau_max))
        return tau


def run_bench(
    robot: str = "phantom",
    ticks: int = 20_000,
    seed: int = 0,
    settings: MPCSettings | None = None,
    *,
    arm: LinearArm | None = None,
    jump: float = 2e-3,
    jump_every: int = 1000,
    warmup: int = 500,
    disable_gc: bool = True,
    progress: Callable[[int, int], None] | None = None,
    controller: str = "python",
    reading_delay: int = 0,
) -> dict:
    """Run the benchmark and return its results (JSON-serialisable ``dict``).

    Parameters
    ----------
    robot : str
        Registered robot name (ignored if ``arm`` is given).
    ticks : int
        Timed ticks, after ``warmup`` untimed ones [ticks].
    seed : int
        Seed of the reference's random phases and jump directions.
    settings : MPCSettings | None
        Controller settings (default ``MPCSettings()``).
    jump, jump_every : float, int
        Reference jumps [m] every ``jump_every`` ticks (0 disables) to exercise active bounds.
    disable_gc : bool
        Disable Python's garbage collector during the loop.
    controller : str
        ``"python"``, or ``"c"`` to also run the whole exported C controller in a loop of its
        own on the same reference (built once and cached, :mod:`rhmpc.compiled`).
    reading_delay : int
        The exported controller's readings come this many ticks late [ticks] (its observer
        fuses each into its own tick and predicts forward: a robot behind a middleware).
    """
    if ticks < 1:
        raise ValueError(f"ticks must be >= 1, got {ticks}")
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    arm = arm if arm is not None else linearize(load_robot(robot))
    settings = settings if settings is not None else MPCSettings()
    t_build = time.perf_counter()
    library = bench_controller(arm, settings)
    build_s = time.perf_counter() - t_build
    mpc = library.mpc
    total = warmup + ticks
    run = _Ticks(library, total)
    traj = heart_like_reference(total + mpc.N + 1, arm.Ts, np.random.default_rng(seed), arm.y0,
                                jump=jump, jump_every=jump_every)
    x = np.zeros(arm.nx)
    x[: mpc.nu] = np.linalg.pinv(arm.C[:, : mpc.nu]) @ (traj[0] - arm.y0)
    gc_was_enabled = gc.isenabled()
    if disable_gc:
        gc.collect()
        gc.disable()
    try:
        for k in range(total):
            tau = run.tick(k, x, traj[k + 1 : k + 1 + mpc.N])
            x = arm.A @ x + arm.B @ tau
            run.err[k] = float(np.linalg.norm(arm.C @ x + arm.y0 - traj[k + 1]))
            if progress is not None and (k + 1) % 1000 == 0:
                progress(k + 1, total)
    finally:
        if disable_gc and gc_was_enabled:
            gc.enable()
    header = {"robot": robot, "ticks": ticks, "warmup_ticks": warmup, "seed": seed,
              "gc_disabled": disable_gc, "build_s": build_s}
    result = {**header, **_summary(run, slice(warmup, total)), "settings": to_dict(settings)}
    if controller == "c":
        result.update(exported_ticks(robot, settings, traj, warmup, disable_gc, reading_delay))
    return result


def _summary(run: _Ticks, sl: slice) -> dict:
    """The Python controller's figures over the timed ticks ``sl``."""
    us = 1e-3
    tick, g, e = run.tick_ns[sl] * us, run.gain_ns[sl] * us, run.exact_ns[sl] * us
    level, every = run.level[sl], run.every_ns[sl] * us
    u0 = run.u0_err[sl]
    stats = run.controller.stats
    return {
        "nz": run.mpc.qp.nz,
        "tick_us": percentiles(tick),
        "screened_ticks": int(run.screened[sl].sum()),
        # the screening cascade: ticks settled by each level (1 unconstrained minimiser, 2 the
        # torque-box QP, 3 the configured solver; 0 = no QP) and the MPC tick per level
        "levels": {str(v): int(np.sum(level == v)) for v in (0, 1, 2, 3)},
        "level_tick_us": {str(v): percentiles(tick[level == v]) for v in (1, 2, 3)
                          if np.any(level == v)},
        "box_iterations": (percentiles(run.box_iters[sl][level == 2]) if np.any(level == 2)
                           else None),
        "osqp_tick_us": percentiles(every),
        "osqp_u0_error_max_frac": float(run.every_err[sl].max()),
        "solve_us": percentiles(run.solve_ns[sl] * us),
        "iterations": percentiles(run.iters[sl]),
        "gain_tick_us": percentiles(g),
        "numpy_gain_us": percentiles(run.numpy_ns[sl] * us),
        "ratio_gain_to_numpy": _ratio(g, run.numpy_ns[sl] * us),
        "exact_tick_us": percentiles(e),
        "exact_iterations": percentiles(run.exact_iters[sl]),
        "exact_failures": int(run.exact_failures),
        "ratio_tick_to_gain": _ratio(tick, g),
        "ratio_tick_to_exact": _ratio(tick, e),
        "ratio_osqp_tick_to_gain": _ratio(every, g),
        "controller": "mpc",
        "fallbacks": dict(stats.fallbacks),
        "failures": dict(stats.failures),
        "osqp_unsolved": int(run.every_failures),
        "u0_error_max_frac": float(u0.max()),
        "u0_error_p99_frac": float(np.percentile(u0, 99)),
        # on the ticks levels 1 and 2 settled (exact, so rounding only against DAQP)
        "u0_error_cascade_max_frac": float(u0[(level == 1) | (level == 2)].max(initial=0.0)),
        "active_bound_ticks": int(run.active[sl].sum()),
        "tracking_rms_mm": float(1e3 * np.sqrt(np.mean(run.err[sl] ** 2))),
        "tracking_max_mm": float(1e3 * run.err[sl].max()),
        "versions": {"python": platform.python_version(), "numpy": np.__version__,
                     "osqp": _version("osqp"), "daqp": _version("daqp")},
    }
