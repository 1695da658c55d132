"""Per-tick timing benchmark of the MPC, with two references measured in the same run.

The controller runs alone, in closed loop with its own linear model (x⁺ = A x + B τ, not timed),
on a moving heart-like reference with occasional reference jumps that saturate the torque
bounds (so that the QP has active constraints). Every tick measures, with
``time.perf_counter_ns``:

* the MPC tick ``mpc.step(x, r)`` (whole call) with the given settings (by default screening
  on: OSQP runs only on ticks where the unconstrained minimiser violates a bound);
* the same MPC with OSQP on *every* tick (:class:`EveryTick`: levels 1 and 2 of the cascade
  skipped), whole call and its parts (``mpc.stats.parts_ns``), fed the same state and reference;
* the *gain tick* g (:class:`rhmpc.timing.yardstick.GainTick`): the unconstrained gain on
  p = [x; r; u_{−1}], u = K p + k₀ — the yardstick every timing is a multiple of — and the same
  mat-vec in plain NumPy (``K @ concatenate(...) + k0``), so that g reads as what it is;
* an *exact tick*: the same QP (same P, q, A, l, u) solved by the active-set solver DAQP,
  hot-started from its previous active set. Its u0 is the accuracy reference:
  ``u0_error = |u0_mpc − u0_exact| / τ_max`` per joint (τ_max = the robot's torque limit);
* with ``controller="c"``, the whole exported controller of ``rhmpc export``
  (:mod:`rhmpc.control.export`: the generalized predictor's refresh, the observer, the MPC and
  the cancellation) in a closed loop of its own on the same linear model and reference: a sensor
  samples the reference every ``downsample`` ticks (one tick late), the model is driven by the
  MPC torque, and every tick, refresh ticks included, is timed inside C
  (``clock_gettime(CLOCK_MONOTONIC)``) beside the gain tick on the C's own state and points:
  ``exported_tick_us`` and ``exported_tick_g``; ``c_tick_us``, the ticks without a refresh;
  and, replayed after the timed loop with the Python controller it was generated from fed the
  same samples and encoder readings, ``c_vs_python_max_frac`` = max over the ticks of
  ``|τ_C − τ_Python|`` / τ_max.
"""

from __future__ import annotations

import dataclasses
import gc
import math
import platform
import time
from collections.abc import Callable
from importlib.metadata import version as _version

import numpy as np

from rhmpc.bench.exported import exported_ticks, percentiles
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.offset import OutputOffset
from rhmpc.control.settings import MPCSettings
from rhmpc.experiment.tables import to_dict
from rhmpc.robots import linearize, load_robot
from rhmpc.robots.linearize import LinearArm
from rhmpc.sim.loop.metrics import warm_ns
from rhmpc.timing.yardstick import GainTick, numpy_gain_step

#: Controllers :func:`run_bench` can time: the Python MPC alone, or with its compiled twin.
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
    """p = [x; r_1..r_N; u_{−1}; d] in a preallocated buffer, d by forward kinematics as in the
    controller (:class:`rhmpc.control.offset.OutputOffset`), so that the exact tick solves the QP
    the controller solves."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        qp = mpc.qp
        self.p = np.zeros(qp.npar)
        self._nx, self._nr, self._nu = qp.nx, qp.N * qp.ny, qp.nu
        self._d = self.p[self._nx + self._nr + self._nu :]
        self._offset = OutputOffset(mpc.arm) if mpc.settings.offset_correction else None

    def fill(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> bool:
        """Write p; False if it is not finite."""
        p = self.p
        p[: self._nx] = x
        p[self._nx : self._nx + self._nr] = ref.reshape(-1)
        p[self._nx + self._nr : self._nx + self._nr + self._nu] = u_prev
        if self._offset is not None:
            self._offset(x, out=self._d)
        return math.isfinite(p.sum())


class EveryTick(RecedingHorizonMPC):
    """Reference 1: the MPC with its QP given to OSQP on every tick (no screening, no back-off
    after its failures)."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        super().__init__(mpc.arm, dataclasses.replace(mpc.settings, backoff_max_ticks=0))

    def _level1(self) -> bool:
        return False

    def _box_solved(self) -> bool:
        return False


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

    COLUMNS = ("tick_ns", "every_ns", "gain_ns", "numpy_ns", "exact_ns", "parts_ns", "iters",
               "exact_iters", "u0_err", "every_err", "active", "screened", "level", "box_iters",
               "err")

    def __init__(self, mpc: RecedingHorizonMPC, total: int) -> None:
        arm = mpc.arm
        self.mpc, self.arm = mpc, arm
        self.every = EveryTick(mpc)
        self.gain, self.exact = GainTick(mpc), ExactTick(mpc)
        self.numpy_gain = numpy_gain_step(self.gain._K, self.gain._k0)
        self.tau_max = np.asarray(arm.torque_limit, dtype=float)
        for name in self.COLUMNS:
            shape = (total, 4) if name == "parts_ns" else total
            dtype = float if name.endswith("err") else bool if name in ("active", "screened") \
                else np.int64
            setattr(self, name, np.zeros(shape, dtype=dtype))
        self.exact_failures = 0

    def tick(self, k: int, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """Time every controller on tick ``k`` with state ``x`` and points ``ref``; returns τ."""
        mpc, every, exact, clock = self.mpc, self.every, self.exact, time.perf_counter_ns
        u_prev, n_screened = mpc.u_prev, mpc.stats.screened
        t0 = clock()
        tau = mpc.step(x, ref)
        t1 = clock()
        self.gain_ns[k] = warm_ns(self.gain, x, ref, u_prev)
        self.numpy_ns[k] = warm_ns(self.numpy_gain, x, ref, u_prev)
        t2 = clock()
        u_exact = exact(x, ref, u_prev)
        t3 = clock()
        every.u_prev = u_prev  # the same QP as the default controller's and DAQP's
        tau_every = every.step(x, ref)
        t4 = clock()
        self.tick_ns[k], self.exact_ns[k] = t1 - t0, t3 - t2
        self.every_ns[k] = t4 - t3
        self.screened[k] = mpc.stats.screened > n_screened
        self.level[k], self.box_iters[k] = mpc.stats.level, mpc.stats.box_iterations
        self.parts_ns[k], self.iters[k] = every.stats.parts_ns, every.stats.iterations
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
    """
    if ticks < 1:
        raise ValueError(f"ticks must be >= 1, got {ticks}")
    if controller not in CONTROLLERS:
        raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
    arm = arm if arm is not None else linearize(load_robot(robot))
    settings = settings if settings is not None else MPCSettings()
    t_build = time.perf_counter()
    mpc = RecedingHorizonMPC(arm, settings)
    build_s = time.perf_counter() - t_build
    total = warmup + ticks
    run = _Ticks(mpc, total)
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
        result.update(exported_ticks(robot, settings, traj, warmup, disable_gc))
    return result


def _summary(run: _Ticks, sl: slice) -> dict:
    """The Python controller's figures over the timed ticks ``sl``."""
    us = 1e-3
    tick, g, e = run.tick_ns[sl] * us, run.gain_ns[sl] * us, run.exact_ns[sl] * us
    level, every = run.level[sl], run.every_ns[sl] * us
    u0, parts = run.u0_err[sl], run.parts_ns[sl] * us
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
        **{f"{name}_us": percentiles(parts[:, i])
           for i, name in enumerate(("reference", "update", "solve", "output"))},
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
        "controller": "python",
        "fallbacks": dict(run.mpc.stats.fallbacks),
        "failures": dict(run.mpc.stats.failures),
        "osqp_fallbacks": dict(run.every.stats.fallbacks),
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
