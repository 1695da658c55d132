"""Level 3 of the screening cascade: the condensed QP in OSQP, set up once.

``min ½vᵀPv + qᵀv, l ≤ Av ≤ u`` by ADMM (Stellato et al., "OSQP: an operator splitting solver
for quadratic programs", Math. Prog. Comp. 12, 2020), set up once with ``P``, ``A`` and the
settings; per tick only the vectors change (``update_data_vec``), as in OSQP's examples. The
options are those the exported C reproduces (OSQP's generated code in vectors mode): a fixed
step ρ (no adaptation: its KKT matrix is factorised once), no polishing, no timer, no scaling
(the QP is scaled physically: inputs by u_max, envelope rows to unit norm), the residuals
checked every 5 iterations and the duality gap not required (the envelope's slack penalty ρ₁
turns slack noise into a gap far above the tolerance).
"""

from __future__ import annotations

import numpy as np
import osqp
import scipy.sparse as sp

from rhmpc.control.qp import CondensedQP
from rhmpc.control.settings import MPCSettings

#: OSQP statuses other than "solved", as the failure reasons the controller counts.
STATUS_REASON = {
    osqp.SolverStatus.OSQP_SOLVED_INACCURATE: "solved_inaccurate",
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE: "primal_infeasible",
    osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE: "primal_infeasible",
    osqp.SolverStatus.OSQP_DUAL_INFEASIBLE: "dual_infeasible",
    osqp.SolverStatus.OSQP_DUAL_INFEASIBLE_INACCURATE: "dual_infeasible",
    osqp.SolverStatus.OSQP_MAX_ITER_REACHED: "max_iter",
    osqp.SolverStatus.OSQP_TIME_LIMIT_REACHED: "time_limit",
    osqp.SolverStatus.OSQP_NON_CVX: "non_convex",
    osqp.SolverStatus.OSQP_SIGINT: "interrupted",
    osqp.SolverStatus.OSQP_UNSOLVED: "unsolved",
}
SOLVED = int(osqp.SolverStatus.OSQP_SOLVED)


class OSQPSolver:
    """The condensed QP in OSQP (module docstring); ``osqp`` is the solver object that
    ``rhmpc export`` generates C from."""

    def __init__(self, qp: CondensedQP, s: MPCSettings) -> None:
        self.osqp = osqp.OSQP()
        self.osqp.setup(
            sp.csc_matrix(np.triu(qp.P)), qp.f0.copy(), sp.csc_matrix(qp.A), qp.l0.copy(),
            qp.u0.copy(), verbose=False, eps_abs=s.osqp_eps_abs, eps_rel=0.0,
            max_iter=s.max_iter, rho=s.osqp_rho, adaptive_rho=False, check_termination=5,
            check_dualgap=False, polishing=False, scaling=0, warm_starting=True)
        self._result = None

    def update(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, bounds: bool) -> None:
        """New linear cost ``q`` and, if ``bounds``, new ``l``/``u`` (P and A never change)."""
        if bounds:
            self.osqp.update(q=q, l=lower, u=upper)
        else:
            self.osqp.update(q=q)

    def warm_start(self, x: np.ndarray, y: np.ndarray | None) -> None:
        """Start the next solve from primal ``x`` and dual ``y`` (``None``: OSQP's own)."""
        self.osqp.warm_start(x=x, y=y)

    def solve(self) -> tuple[int, int, np.ndarray]:
        """(status value, iterations, primal v)."""
        self._result = res = self.osqp.solve(raise_error=False)
        return res.info.status_val, res.info.iter, res.x

    def last_solution(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the last iterate (primal, dual), whatever its status."""
        if self._result is None:
            raise RuntimeError("no solve has run yet")
        return np.array(self._result.x, dtype=float), np.array(self._result.y, dtype=float)
