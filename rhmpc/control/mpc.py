"""`RecedingHorizonMPC`: the condensed, move-blocked tracking QP solved every tick by the screening
cascade.

Built once (:func:`rhmpc.control.qp.build_condensed_qp`: CasADi → numpy data → OSQP's setup);
each tick then only does::

    d = p(q0 + x̂_q) − (C x̂ + y0)       (output offset: one forward-kinematics call)
    p = [x; r_1..r_N; u_{−1}; d]        (copy into a preallocated buffer, finiteness check)
    level 1: ẑ* = K_z [p; 1]            (K_z = −W F_z, W = P_zz⁻¹: the unconstrained minimiser)
             if H [ẑ*; 0; p_B; 1] ≤ 0    (every row of l0 − G p ≤ A [ẑ*; 0] ≤ u0 − G p, signed,
                                          :func:`rhmpc.control.qp.screening_rows`): done
    l, u = l0 − G p, u0 − G p           (envelope rows: only the state and offset columns)
    q_z = F_z p + f0_z                  (one mat-vec; the slacks' q is the constant ρ₁)
    level 2: the torque-box QP by active set (:mod:`rhmpc.control.box_qp`); if it converges, its
             KKT certificate holds and every envelope row holds at [z; 0]: v = [z; 0], done;
             if it stops at its cap (box_max_iter solves): the fallback
    level 3: OSQP: update(q, l, u), warm start from the last plan shifted one tick, solve
    τ = clip(u_max ∘ ẑ_0, −u_max, u_max)   if the status is "solved", else the fallback

A capped level 2 takes the fallback rather than level 3: ADMM bounded at ``max_iter``
iterations does not finish what ``box_max_iter`` exact active-set solves could not.

Back-off
    A tick stream the solver cannot settle (a reference out of the arm's reach, an envelope the
    state has left) would pay levels 2 and 3 on every tick for nothing. After k consecutive
    failed ticks, levels 2 and 3 rest for ``min(2ᵏ − 1, backoff_max_ticks)`` ticks (binary
    exponential back-off, as Ethernet's retransmissions: Metcalfe & Boggs, *Commun. ACM*
    19(7), 1976), while level 1 still runs every tick and the fallback acts (reason
    ``"backoff"``). Any solved tick ends the back-off.

The screening cascade is exact, not an approximation. Level 1: with the slacks at 0 and every
row satisfied, the point satisfies the QP's KKT conditions (zero multipliers on the envelope and
torque rows, multiplier ρ₁ on each slack's bound s ≥ 0), and P ≻ 0 makes it unique. It checks
every row. Level 2 is the same argument with the torque rows' multipliers of the box QP: the
envelope rows' multipliers are zero, so the box QP's KKT conditions are the full QP's (proof in
:mod:`rhmpc.control.box_qp`). It checks every envelope row; the torque rows are its own
constraints. The tests hold the cascade to a plain solve of the same QP.

Warm start: OSQP's next solve starts from the last plan shifted one tick (its primal; its dual
is OSQP's own after a solve, zero but −ρ₁ on the slack bounds after a screened tick or a
fallback); after a solve stopped at ``max_iter`` it starts from that iterate, primal and dual,
shifted, so that a solve that needs more iterations finishes over a few ticks.

A tick whose solve is not "solved" never uses OSQP's ``x``: it takes a fallback of
:mod:`rhmpc.control.fallback` (the shifted plan, the clipped LQ input if it keeps the envelope,
braking, zero torque) and counts the event in :attr:`stats`.
"""

from __future__ import annotations

import math
import time

import numpy as np

from rhmpc.control.box_qp import BoxQP, BoxQPSettings
from rhmpc.control.fallback import FallbackChain, MPCStats
from rhmpc.control.offset import OutputOffset
from rhmpc.control.osqp_solver import SOLVED, STATUS_REASON, OSQPSolver
from rhmpc.control.qp import CondensedQP, build_condensed_qp, screening_rows
from rhmpc.control.settings import MPCSettings
from rhmpc.robots.linearize import LinearArm

#: Failure reasons counted in :attr:`MPCStats.failures` besides OSQP's statuses.
EXTRA_REASONS = ("nonfinite_input", "nonfinite_solution", "solver_error", "injected",
                 "box_max_iter", "backoff", "encoder_fault")
#: A slack above this [its unit] counts the tick as relaxing the envelope (``stats.relaxed``).
RELAXED_SLACK = 1e-2

__all__ = ["EXTRA_REASONS", "MPCStats", "RecedingHorizonMPC"]


class RecedingHorizonMPC(FallbackChain):
    """Receding-horizon MPC for the linearised arm, tracking N end-effector reference points.

    Parameters
    ----------
    arm : LinearArm
        Discrete model x⁺ = A x + B u, y = C x + y0 (``rhmpc.robots.linearize``); its robot gives
        the output offset and the joint limits.
    settings : MPCSettings
        Horizon, weights, bounds and solver settings (see
        :class:`rhmpc.control.settings.MPCSettings` for the cost and constraints).

    Raises
    ------
    ValueError
        At build time, if the settings do not fit the arm (see :func:`build_condensed_qp`).

    Notes
    -----
    ``step(x, ref)`` takes ``x`` (nx,) = [q − q0; q̇] [rad, rad/s] and ``ref`` (N, 3) absolute
    end-effector positions r_1..r_N for the next N ticks [m], and returns τ_mpc (nu,) [N·m],
    always finite and within ``±u_max``. Non-finite inputs raise nothing: they take the fallback.
    With ``offset_correction`` the output offset d is computed from ``x`` inside ``step``.
    """

    def __init__(self, arm: LinearArm, settings: MPCSettings | None = None) -> None:
        self.settings = settings if settings is not None else MPCSettings()
        if not isinstance(self.settings, MPCSettings):
            raise ValueError(f"settings must be MPCSettings, got {type(self.settings).__name__}")
        self.arm = arm
        self.qp: CondensedQP = build_condensed_qp(arm, self.settings)
        qp = self.qp
        self.N, self.nx, self.nu, self.ny = qp.N, qp.nx, qp.nu, qp.ny
        self.u_max = qp.u_max.copy()
        self.u_max.setflags(write=False)

        # -- per-tick buffers and views ------------------------------------------------------
        # One mat-vec per tick gives q: p_ext = [p; 1], F_ext = [F, f0], q = F_ext p_ext. The
        # finiteness check before it is p_extᵀp_ext (squares: no inf − inf, so no FP warning).
        nx, N, ny = self.nx, self.N, self.ny
        self._p_ext = np.zeros(qp.npar + 1)
        self._p_ext[-1] = 1.0
        self._p = self._p_ext[:-1]
        self._p_x = self._p_ext[:nx]
        self._p_r = self._p_ext[nx:nx + N * ny]
        self._p_r2 = self._p_r.reshape(N, ny)  # a view: ref is copied in without a reshape
        self._p_u = self._p_ext[nx + N * ny:nx + N * ny + self.nu]
        self._p_d = self._p_ext[nx + N * ny + self.nu:-1]
        self._offset = (OutputOffset(arm, out=self._p_d, state=self._p_x)
                        if self.settings.offset_correction else None)
        self._x_shape, self._ref_shape = (nx,), (N, ny)
        self._F_ext = np.ascontiguousarray(np.column_stack([qp.F, qp.f0]))
        self._q = np.empty(qp.nv)
        self._l = qp.l0.copy()
        self._u = qp.u0.copy()
        self._g = np.empty(qp.A.shape[0])
        self._G_take = qp.bound_index  # p[G_take] = p[bound_columns]
        self._G = np.ascontiguousarray(qp.G[:, qp.bound_columns])
        self._nz, self._nv = qp.nz, qp.nv
        self._shift, self._shift_dual = qp.shift, qp.shift_dual
        self._scale0 = qp.u_max.copy()
        self._Z_ext = np.ascontiguousarray(qp.minimiser)
        # Level 1 in two mat-vecs (:meth:`_level1`): w = [ẑ*; 0; p_B; 1] with ẑ* = K_z p_ext
        # (K_z = −W F_z), and every row of l ≤ A [ẑ*; 0] ≤ u as a row of H w ≤ 0.
        self._w = np.zeros(qp.nv + len(qp.bound_columns) + 1)
        self._w[-1] = 1.0
        self._w_z, self._v_star = self._w[: qp.nz], self._w[: qp.nv]
        self._w_p = self._w[qp.nv : -1]
        self._H = screening_rows(qp)
        self._c = np.empty(self._H.shape[0])
        # The screening cascade works on q_z (the slacks' part of q is the constant ρ₁):
        # level 1 ẑ* = −W q_z, level 2 the box QP on the same W (rhmpc.control.box_qp).
        self._q[qp.nz:] = qp.f0[qp.nz:]
        self._q_z = self._q[: qp.nz]
        self._F_z = np.ascontiguousarray(self._F_ext[: qp.nz])
        cap = self.settings.box_max_iter
        self.box = BoxQP(qp.P[: qp.nz, : qp.nz], BoxQPSettings(
            max_iter=BoxQPSettings.pdas_iter + qp.nz if cap is None else cap))
        self._K_z = np.ascontiguousarray(self.box._negW @ self._F_z)
        self._A_env = np.ascontiguousarray(qp.A[qp.nv:, : qp.nz])
        self._g_env = np.empty(qp.A.shape[0] - qp.nv)
        self._level = 0
        # Multipliers of a screened solution: 0 on every row but the slack bounds s ≥ 0, whose
        # multiplier is −ρ₁ (stationarity in s at s = 0): ADMM's start, so that it need not
        # build ρ₁ up over its iterations.
        self._y_zero = np.zeros(qp.A.shape[0])
        self._y_zero[qp.nz:qp.nv] = -self.settings.envelope_penalty
        self._neg_umax = -qp.u_max
        self._nu_ = self.nu
        self._solver = OSQPSolver(qp, self.settings)
        self._osqp = self._solver.osqp  # what rhmpc export generates C from
        self.stats = MPCStats()
        self.reset()

    # -- public API --------------------------------------------------------------------------
    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the plan and warm start, zero the counters, and set u_{−1} (default 0) [N·m].

        A non-zero ``u_prev`` gives a bumpless start when the MPC takes over from another
        controller (the rate term R_Δ penalises the change from it).
        """
        # u_{−1}: the last returned torque lives in the parameter buffer.
        self._p_u[:] = 0.0 if u_prev is None else np.clip(u_prev, -self.u_max, self.u_max)
        self._plan: np.ndarray | None = None  # (nv,) [ẑ; s] of the last good solve
        self._plan_age = 0
        self._ws_x: np.ndarray | None = None
        self._ws_y: np.ndarray | None = None
        self._forced: list[str] = []
        self._streak = 0  # consecutive failed ticks
        self._rest = 0  # ticks levels 2 and 3 still rest
        self._last_screened = False
        self._ws_pending = False
        self.stats = MPCStats()
        self._solver.warm_start(np.zeros(self.qp.nv), self._y_zero)

    def force_failures(self, count: int = 1, reason: str = "injected") -> None:
        """Make the next ``count`` solves report failure ``reason`` (tests, fault injection).

        The solve still runs (timing stays realistic); its result is discarded as for a real
        failure and the fallback is applied.
        """
        if count < 0:
            raise ValueError(f"count must be >= 0, got {count}")
        self._forced.extend([reason] * int(count))

    def last_solution(self) -> tuple[np.ndarray, np.ndarray]:
        """Primal ẑ and dual y of the last tick's QP, as copies.

        After a screened tick: ([ẑ*; 0], y) with y = 0 but −ρ₁ on the slack bounds (level 1),
        or the box multipliers on the torque rows (level 2); otherwise the solver's last
        iterate, whatever its status.
        """
        if self._last_screened:
            y = self._y_zero.copy()
            if self._level == 2:
                y[: self._nz] = self.box.mu
            return self._plan.copy(), y
        return self._solver.last_solution()

    @property
    def u_prev(self) -> np.ndarray:
        """The torque returned by the last tick (u_{−1} of the next QP) [N·m].

        Assign to it when another torque than the returned one acted (e.g. another controller
        ran this tick); the value is clipped to ±u_max. Non-finite values raise ``ValueError``.
        """
        return self._p_u.copy()

    @u_prev.setter
    def u_prev(self, value: np.ndarray) -> None:
        value = np.asarray(value, dtype=float)
        if value.shape != (self.nu,) or not np.all(np.isfinite(value)):
            raise ValueError(f"u_prev must be {self.nu} finite torques [N·m], got {value!r}")
        self._p_u[:] = np.clip(value, -self.u_max, self.u_max)

    def step(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """One control tick: MPC torque τ_mpc (nu,) [N·m] for state ``x`` and reference ``ref``.

        Raises
        ------
        ValueError
            Only for wrong shapes (a programming error); never for non-finite values.
        """
        t0 = time.perf_counter_ns()
        stats = self.stats
        stats.ticks += 1
        stats.level = 0
        stats.box_iterations = 0
        if not self._set_parameters(x, ref):
            stats.parts_ns[:] = [time.perf_counter_ns() - t0, 0, 0, 0]
            stats.iterations = 0
            stats.solve_time = 0.0
            return self._fallback("nonfinite_input", inputs_finite=False)
        if not self._forced and self._level1():
            return self._screened_output(t0, self._v_star, 1)
        if self.qp.param_bounds:
            np.dot(self._G, self._p[self._G_take], out=self._g)
            np.subtract(self.qp.l0, self._g, out=self._l)
            np.subtract(self.qp.u0, self._g, out=self._u)
        if self._rest > 0 and not self._forced:
            self._rest -= 1
            stats.level = 1
            return self._unsolved(t0, "backoff")
        np.dot(self._F_z, self._p_ext, out=self._q_z)
        if not self._forced:
            if self._box_solved():
                v = np.zeros(self._nv)
                v[: self._nz] = self.box.z
                return self._screened_output(t0, v, 2)
            stats.box_iterations = self.box.iterations
            if self.box.capped:
                stats.level = 2
                return self._unsolved(t0, "box_max_iter")
        return self._solver_tick(t0)

    def _set_parameters(self, x: np.ndarray, ref: np.ndarray) -> bool:
        """Write p = [x; r; u_{−1}; d(x)] (d: the offset correction); False if not all finite."""
        x = np.asarray(x, dtype=float)
        ref = np.asarray(ref, dtype=float)
        if x.shape != self._x_shape or ref.shape != self._ref_shape:
            raise ValueError(
                f"step expects x {self._x_shape} and ref {self._ref_shape}, "
                f"got {x.shape}, {ref.shape}"
            )
        self._p_x[:] = x
        self._p_r2[...] = ref
        if not math.isfinite(np.vdot(x, x)):
            return False  # (and no offset of a non-finite state)
        if self._offset is not None:
            self._offset.evaluate()  # d of the x in p, into p (NaN where x is not finite)
        return math.isfinite(np.vdot(self._p_ext, self._p_ext))  # NaN, ±inf, > 1e154: no warning

    def _solver_tick(self, t0: int) -> np.ndarray:
        """Level 3: OSQP, warm-started; its result or the fallback chain."""
        clock, stats = time.perf_counter_ns, self.stats
        self._last_screened = False
        self._level = 3
        stats.level = 3
        t1 = clock()
        try:
            self._solver.update(self._q, self._l, self._u, self.qp.param_bounds)
            self._apply_warm_start()
            t2 = clock()
            status, iters, z = self._solver.solve()
        except Exception:  # the loop must survive any solver error
            t2 = clock()
            stats.parts_ns[:] = [t1 - t0, t2 - t1, 0, 0]
            stats.iterations = 0
            stats.solve_time = 0.0
            return self._fallback("solver_error", inputs_finite=True)
        t3 = clock()
        stats.iterations = iters
        stats.solve_time = (t3 - t2) * 1e-9
        if self._forced:
            reason = self._forced.pop(0)
        else:
            reason = None if status == SOLVED else STATUS_REASON.get(status, f"status_{status}")
        if reason is None:
            tau = z[: self._nu_] * self._scale0
            if not math.isfinite(np.dot(tau, tau)):
                reason = "nonfinite_solution"
        out = self._rejected(reason) if reason is not None else self._accepted(tau, z)
        stats.parts_ns[:] = [t1 - t0, t2 - t1, t3 - t2, clock() - t3]
        return out

    def _apply_warm_start(self) -> None:
        """OSQP's start (module docstring): the shifted plan, or its own iterate."""
        if self._ws_pending:
            self._ws_x, self._ws_y = self._shift @ self._plan, self._y_zero
            self._ws_pending = False
        if self._ws_x is not None:
            self._solver.warm_start(self._ws_x, self._ws_y)
            self._ws_x = self._ws_y = None

    def _accepted(self, tau: np.ndarray, z: np.ndarray) -> np.ndarray:
        """A solved QP: τ clipped to ±u_max, the plan kept, the next warm start prepared."""
        stats = self.stats
        np.maximum(tau, self._neg_umax, out=tau)
        np.minimum(tau, self.u_max, out=tau)
        if self._nv > self._nz:
            slack = float(z[self._nz:].max())
            if slack > RELAXED_SLACK:
                stats.relaxed += 1
            if slack > stats.slack_max:
                stats.slack_max = slack
        self._p_u[:] = tau  # u_{−1} of the next tick (a copy: the caller owns tau)
        self._plan = z  # a fresh array from OSQP on every solve
        self._plan_age = 0
        self._streak = 0
        self._ws_x = self._shift @ z  # OSQP keeps its own dual
        stats.status = "solved"
        stats.source = "qp"
        return tau

    def _screened_output(self, t0: int, v: np.ndarray, level: int) -> np.ndarray:
        """τ from a screened solution v = [ẑ; 0] of level 1 or 2 (the QP's solution, exactly):
        bookkeeping of a tick without the solver."""
        z = v.copy() if level == 1 else v
        tau = z[: self._nu_] * self._scale0
        if level == 2:  # |ẑ_i| ≤ 1 + primal_tol
            np.maximum(tau, self._neg_umax, out=tau)
            np.minimum(tau, self.u_max, out=tau)
        self._p_u[:] = tau
        self._plan = z
        self._plan_age = 0
        self._streak = 0
        # The next OSQP solve starts from this plan shifted (computed only when it runs); all
        # multipliers are zero here.
        self._ws_pending = True
        self._last_screened = True
        self._level = level
        stats = self.stats
        stats.iterations = 0
        stats.solve_time = 0.0
        stats.level = level
        stats.box_iterations = self.box.iterations if level == 2 else 0
        if level == 1:
            stats.screened += 1
        else:
            stats.boxed += 1
        stats.status = "solved"
        stats.source = "qp"
        stats.parts_ns[0] = time.perf_counter_ns() - t0
        stats.parts_ns[1] = stats.parts_ns[2] = stats.parts_ns[3] = 0
        return tau

    def _level1(self) -> bool:
        """Level 1: ẑ* = K_z p_ext (K_z = −W F_z, in ``_w``, slacks 0); True if [ẑ*; 0]
        satisfies every constraint row, H [ẑ*; 0; p_B; 1] ≤ 0 (then it is the QP's solution).
        """
        np.dot(self._K_z, self._p_ext, out=self._w_z)
        if self._w_p.size:
            self._w_p[:] = self._p[self._G_take]
        c = np.dot(self._H, self._w, out=self._c)
        return bool(c[c.argmax()] <= 0.0)  # argmax: a quarter of max()'s cost; NaN → False

    def _box_solved(self) -> bool:
        """Level 2: the torque-box QP solved exactly (KKT certificate), and every envelope row
        holds at [z; 0] (then it is the full QP's solution; :mod:`rhmpc.control.box_qp`)."""
        box = self.box
        # its start: the unconstrained minimiser −W q_z (as the compiled controller computes it)
        if not box.solve(self._q_z, np.dot(box._negW, self._q_z, out=self._w_z)):
            return False
        if self._g_env.size == 0:
            return True
        g = np.dot(self._A_env, box.z, out=self._g_env)
        nv = self._nv
        return bool((g - self._u[nv:]).max() <= 0.0 and (self._l[nv:] - g).max() <= 0.0)
