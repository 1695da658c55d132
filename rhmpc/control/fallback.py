"""What the MPC applies when a tick's QP result cannot be used, and its bookkeeping.

The order (:meth:`rhmpc.control.mpc.RecedingHorizonMPC` applies it):

1. ``"plan"``: the last good plan, shifted to the current tick, for at most
   ``plan_fallback_ticks`` ticks. It was computed under the envelope, so it respects it (as
   far as the model is right).
2. ``"lq"``: the first input of the unconstrained minimiser, clipped to the torque bounds, but
   only if the whole clipped input sequence keeps every envelope row of the QP at the current
   state (checked by :func:`envelope_holds`).
3. ``"brake"``: otherwise, the torque that would stop the joints within the first move block,
   clipped: ``τ = clip(−M0 q̇ / (n₁ Ts), ±u_max)`` — it only removes kinetic energy.
4. ``"zero"``: when the inputs themselves are not finite (no state to brake from).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

#: Fallback sources, in the order they are tried.
SOURCES = ("plan", "lq", "brake", "zero")


@dataclass
class MPCStats:
    """What the controller did: the last tick, and counters since construction or reset.

    Attributes
    ----------
    ticks : int
        Number of :meth:`RecedingHorizonMPC.step` calls.
    status : str
        Last tick: ``"solved"`` or the failure reason (an OSQP status such as ``"max_iter"``,
        ``"time_limit"``, ``"primal_infeasible"``, or ``"nonfinite_input"``,
        ``"nonfinite_solution"``, ``"solver_error"``, ``"injected"``).
    source : str
        Where the last torque came from: ``"qp"``, ``"plan"``, ``"lq"``, ``"brake"``, ``"zero"``.
    iterations : int
        OSQP iterations of the last tick (0 if no solve ran).
    screened : int
        Ticks solved by level 1 of the screening cascade (the unconstrained minimiser holds
        every row), without calling the solver (their ``source`` is ``"qp"``).
    boxed : int
        Ticks solved by level 2 (the torque-box QP by active set, every envelope row holding:
        :mod:`rhmpc.control.box_qp`), without calling the solver (``source`` ``"qp"``).
    level : int
        Last tick: the cascade level that produced the QP solution (1, 2, or 3 = OSQP), 0 if
        the tick never reached the QP (non-finite inputs).
    box_iterations : int
        Last tick: level 2's active-set solves (also when it was tried and the tick went on to
        level 3), else 0.
    solve_time : float
        Wall time of the last ``solve()`` call [s].
    parts_ns : list[int]
        Last tick's phases [ns]: reference handling (incl. the offset), vector update (incl. warm
        start), OSQP solve, output (status check, clipping, bookkeeping).
    failures : dict[str, int]
        Ticks whose QP result was not used, by reason.
    fallbacks : dict[str, int]
        Ticks served by each fallback: ``"plan"``, ``"lq"``, ``"brake"``, ``"zero"``.
    relaxed : int
        Solved ticks whose plan relaxes the envelope (some slack above 0.01 of its unit, i.e.
        0.01 % of a joint range or 1 µm Cartesian): the soft constraints were needed.
    slack_max : float
        Largest slack of a solved tick [units of :mod:`rhmpc.control.envelope`].
    """

    ticks: int = 0
    status: str = "none"
    source: str = "none"
    iterations: int = 0
    screened: int = 0
    boxed: int = 0
    level: int = 0
    box_iterations: int = 0
    solve_time: float = 0.0
    parts_ns: list[int] = field(default_factory=lambda: [0, 0, 0, 0])
    failures: dict[str, int] = field(default_factory=dict)
    fallbacks: dict[str, int] = field(default_factory=lambda: dict.fromkeys(SOURCES, 0))
    relaxed: int = 0
    slack_max: float = 0.0

    @property
    def fallback_total(self) -> int:
        """Ticks that did not apply the QP solution."""
        return sum(self.fallbacks.values())


def envelope_holds(A: np.ndarray, v: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                   nz: int) -> bool:
    """True if the plan ``v`` (slacks zero) keeps every envelope row: l ≤ A v ≤ u beyond the
    torque and slack rows."""
    g = A[nz:] @ v
    return bool(np.all(g >= lower[nz:]) and np.all(g <= upper[nz:]))


def brake_torque(M0: np.ndarray, velocity: np.ndarray, ticks: int, Ts: float,
                 u_max: np.ndarray) -> np.ndarray:
    """τ = clip(−M0 q̇ / (ticks · Ts), ±u_max) [N·m]: stop the joints in ``ticks`` ticks."""
    return np.clip(-(M0 @ velocity) / (ticks * Ts), -u_max, u_max)


#: Failures whose iterate is carried over to the next tick's warm start.
_CONTINUE = frozenset({"max_iter", "time_limit", "solved_inaccurate", "injected"})
#: Failures that do not lengthen the back-off: no solve was tried, or the failure was injected.
_NO_BACKOFF = frozenset({"nonfinite_input", "injected", "backoff", "encoder_fault"})
#: Longest failure streak the back-off counts (2³⁰ ticks: beyond any ``backoff_max_ticks``).
_STREAK_MAX = 30


class FallbackChain:
    """The ticks whose torque is not the QP's, as :class:`rhmpc.control.mpc.RecedingHorizonMPC`
    takes them (it derives from this class, which works on its state): the chain above, the
    failure counted, the back-off lengthened, the next warm start prepared."""

    def _lq_or_brake(self) -> tuple[np.ndarray, str]:
        """The clipped LQ input if its whole clipped plan keeps the envelope, else braking."""
        v = np.dot(self._Z_ext, self._p_ext)
        np.clip(v, -1.0, 1.0, out=v)
        v[self._nz:] = 0.0
        if not self.qp.param_bounds or envelope_holds(self.qp.A, v, self._l, self._u, self._nz):
            return v[: self.nu] * self._scale0, "lq"
        velocity = self._p_x[self.nx // 2:]
        ticks = self.settings.block_lengths[0]
        return brake_torque(self.arm.M0, velocity, ticks, self.arm.Ts, self.u_max), "brake"

    def _unsolved(self, t0: int, reason: str) -> np.ndarray:
        """A tick that ends without the solver (back-off, a capped level 2): the fallback."""
        self._last_screened = False
        stats = self.stats
        stats.iterations = 0
        stats.solve_time = 0.0
        out = self._fallback(reason, inputs_finite=True)
        stats.parts_ns[:] = [time.perf_counter_ns() - t0, 0, 0, 0]
        return out

    def brake(self, x: np.ndarray, reason: str = "encoder_fault") -> np.ndarray:
        """A tick without the QP, for a fault of the state's source: the torque that stops the
        joints within the first move block (:func:`rhmpc.control.fallback.brake_torque`, from
        the velocity of ``x``; zero if it is not finite), counted as a failure ``reason``."""
        t0 = time.perf_counter_ns()
        stats = self.stats
        stats.ticks += 1
        stats.level = stats.box_iterations = stats.iterations = 0
        stats.solve_time = 0.0
        self._last_screened = False
        velocity = np.asarray(x, dtype=float)[self.nx // 2:]
        ticks = self.settings.block_lengths[0]
        tau = brake_torque(self.arm.M0, velocity, ticks, self.arm.Ts, self.u_max)
        out = self._fallen_back(reason, tau, "brake")
        stats.parts_ns[:] = [time.perf_counter_ns() - t0, 0, 0, 0]
        return out

    def _rejected(self, reason: str) -> np.ndarray:
        """A solve not used: the fallback's torque; an unfinished iterate starts the next solve."""
        out = self._fallback(reason, inputs_finite=True)
        if reason in _CONTINUE:
            # An unfinished solve is a good start for the next, nearly identical QP: carry
            # the ADMM iterate over instead of restarting from the old plan.
            z, y = self.last_solution()
            if np.isfinite(z).all() and np.isfinite(y).all():
                self._ws_x = self._shift @ z
                self._ws_y = self._shift_dual @ y
        return out

    def _fallback(self, reason: str, *, inputs_finite: bool) -> np.ndarray:
        """The fallback chain's torque (plan, clipped LQ or braking, zero), recorded."""
        tau, source = None, "zero"
        k = self._plan_age + 1  # the tick of the plan this one is
        if self._plan is not None and k <= self.settings.plan_fallback_ticks:
            b = self.qp.block_of_tick[min(k, self.N - 1)]
            tau = self._plan[b * self.nu:(b + 1) * self.nu] * self._scale0
            source = "plan"
        if tau is None and inputs_finite:
            tau, source = self._lq_or_brake()
        return self._fallen_back(reason, tau, source)

    def _fallen_back(self, reason: str, tau: np.ndarray | None, source: str) -> np.ndarray:
        """The bookkeeping of a tick whose torque is not the QP's: the failure, the back-off,
        the plan's age, τ (zero if not finite) clipped into u_{−1}, the next warm start."""
        stats = self.stats
        stats.status = reason
        stats.failures[reason] = stats.failures.get(reason, 0) + 1
        if reason not in _NO_BACKOFF:
            self._streak = min(self._streak + 1, _STREAK_MAX)
            self._rest = min(2**self._streak - 1, self.settings.backoff_max_ticks)
        self._plan_age += 1
        if tau is None or not np.all(np.isfinite(tau)):
            tau = np.zeros(self.nu)
            source = "zero"
        tau = np.clip(tau, self._neg_umax, self.u_max)
        stats.source = source
        stats.fallbacks[source] += 1
        self._p_u[:] = tau
        # Next warm start: the plan shifted to the next tick (or cold if there is none).
        self._ws_pending = False
        if self._plan is not None:
            self._ws_x = self._shift @ self._plan
            self._ws_y = self._y_zero
        return tau
