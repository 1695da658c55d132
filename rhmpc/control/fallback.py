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
        Last tick: the cascade level that produced the QP solution (1, 2, or 3 = the configured
        solver), 0 if the tick never reached the QP (non-finite inputs).
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
