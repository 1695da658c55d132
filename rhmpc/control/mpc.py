"""`RecedingHorizonMPC`: the condensed, move-blocked tracking QP, and what the controller's library
needs to solve it every tick by the screening cascade.

Built once (:func:`rhmpc.control.qp.build_condensed_qp`: CasADi → numpy data), and generated into
the library (``rhmpc_mpc.c``, :mod:`rhmpc.control.export`), whose tick does::

    d = p(q0 + x̂_q) − (C x̂ + y0)       (output offset: one forward-kinematics call)
    p = [x; r_1..r_N; u_{−1}; d]        (copy into a preallocated buffer, finiteness check)
    l, u = l0 − G p, u0 − G p           (envelope rows: only the state and offset columns)
    q_z = F_z p + f0_z                  (one mat-vec; the slacks' q is the constant ρ₁)
    level 1: ẑ* = −W q_z                (W = P_zz⁻¹: the unconstrained minimiser)
             if l ≤ A [ẑ*; 0] ≤ u         (every row: torque, slack and envelope): done
    level 2: the torque-box QP by active set (below); if it converges, its
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
envelope rows' multipliers are zero, so the box QP's KKT conditions are the full QP's (proof
below). It checks every envelope row; the torque rows are its own
constraints. The tests hold the cascade to a plain solve of the same QP.

Warm start: OSQP's next solve starts from the last plan shifted one tick (its primal; its dual
is OSQP's own after a solve, zero but −ρ₁ on the slack bounds after a screened tick or a
fallback); after a solve stopped at ``max_iter`` it starts from that iterate, primal and dual,
shifted, so that a solve that needs more iterations finishes over a few ticks.

A tick whose solve is not "solved" never uses OSQP's ``x``: it takes the
fallback chain (the shifted plan for ``plan_fallback_ticks``; the clipped LQ input if its
whole clipped plan keeps every envelope row; else braking, τ = clip(−M0 q̇ / (n₁ Ts), ±u_max),
which stops the joints within the first move block; zero torque when the inputs are not
finite) and counts the event in the controller's ``stats``.

Level 2, the torque-box QP ``min ½ zᵀ H z + q_zᵀ z, −1 ≤ z ≤ 1`` (H = P_zz), is solved exactly
by active sets on W = H⁻¹ (range-space steps: Nocedal & Wright, *Numerical Optimization*, 2nd
ed., §16.2): first ``pdas_iter`` primal-dual active-set solves (Hintermüller, Ito & Kunisch,
*SIAM J. Optim.* 13(3), 2002), then the dual active set of Goldfarb & Idnani (*Math. Program.*
27, 1983), which terminates; a result is taken only with its KKT certificate
``‖H z + q + E_𝒜 μ‖∞ ≤ ε_kkt (1 + ‖q‖∞)``. If every envelope row holds at [z; 0], z with those
multipliers (zero on the envelope rows, −ρ₁ on the slack bounds) satisfies the full QP's KKT
conditions, and P ≻ 0 makes it the unique optimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.control.qp import CondensedQP, build_condensed_qp
from rhmpc.control.settings import MPCSettings
from rhmpc.robots.linearize import LinearArm

__all__ = ["BoxSettings", "RecedingHorizonMPC"]


@dataclass(frozen=True)
class BoxSettings:
    """Level 2's numbers (module docstring).

    Attributes
    ----------
    max_iter : int
        Cap on the Cholesky solves per tick, both phases together [-].
    pdas_iter : int
        Solves of the primal-dual active set before the dual active set takes over [-].
    primal_tol, dual_tol, kkt_tol : float
        ε_p (a bound is violated when ``|z_i| > 1 + ε_p``), ε_d (an active bound is kept while
        ``b_i μ_i ≥ −ε_d (1 + ‖q‖∞)``), ε_kkt (the certificate) [-].
    """

    max_iter: int
    pdas_iter: int = 3
    primal_tol: float = 1e-9
    dual_tol: float = 1e-9
    kkt_tol: float = 1e-9


class RecedingHorizonMPC:
    """Receding-horizon MPC for the linearised arm, tracking N end-effector reference points:
    the QP and the cascade's data (module docstring), which the controller's library solves.

    Parameters
    ----------
    arm : LinearArm
        Discrete model x⁺ = A x + B u, y = C x + y0 (``rhmpc.robots.linearize``); its robot gives
        the output offset and the joint limits.
    settings : MPCSettings
        Horizon, weights, bounds and solver settings (see
        :class:`rhmpc.control.settings.MPCSettings` for the cost and constraints).

    Attributes
    ----------
    qp : CondensedQP
    hessian : (nz, nz) H = P_zz, the box QP's Hessian
    W : (nz, nz) H⁻¹, by Cholesky
    F_z : (nz, npar + 1) [F, f0] of the block inputs: q_z = F_z [p; 1]
    y_plan : (m,) the multipliers paired with a screened plan: 0 but −ρ₁ on the slack bounds
    box : BoxSettings

    Raises
    ------
    ValueError
        At build time, if the settings do not fit the arm (see :func:`build_condensed_qp`).
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
        nz = qp.nz
        self.hessian = np.ascontiguousarray(0.5 * (qp.P[:nz, :nz] + qp.P[:nz, :nz].T))
        L_inv = np.linalg.inv(np.linalg.cholesky(self.hessian))
        W = L_inv.T @ L_inv  # W = L⁻ᵀ L⁻¹
        self.W = np.ascontiguousarray(0.5 * (W + W.T))
        self.F_z = np.ascontiguousarray(np.column_stack([qp.F, qp.f0])[:nz])
        self.y_plan = np.zeros(qp.A.shape[0])
        self.y_plan[nz:qp.nv] = -self.settings.envelope_penalty
        cap = self.settings.box_max_iter
        self.box = BoxSettings(max_iter=BoxSettings.pdas_iter + nz if cap is None else cap)
