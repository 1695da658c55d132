"""OSQP behind the MPC's solver interface (the same shape as :mod:`rhmpc.control.active_set`).

Set up once with the condensed QP's ``P``, ``A`` and the settings, then per tick only vectors
change (``update_data_vec``), as in the OSQP examples. The public ``OSQP.solve()`` wraps every
result in namespaces (≈ 10 µs per call), so the extension object underneath (``_solver``) is
used directly when it is there, the public API otherwise.
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
    """The condensed QP ``min ½vᵀPv + qᵀv, l ≤ Av ≤ u`` in OSQP (ADMM; Stellato et al., Math.
    Prog. Comp. 12, 2020), set up once; ``want_dual`` returns y from :meth:`solve`."""

    def __init__(self, qp: CondensedQP, s: MPCSettings, want_dual: bool) -> None:
        self.osqp = osqp.OSQP()
        o = s.osqp
        extra = {"time_limit": o.time_limit} if o.time_limit > 0 else {}
        self.osqp.setup(
            sp.csc_matrix(np.triu(qp.P)), qp.f0.copy(), sp.csc_matrix(qp.A), qp.l0.copy(),
            qp.u0.copy(), verbose=False, eps_abs=o.eps_abs, eps_rel=o.eps_rel,
            max_iter=s.max_iter, rho=o.rho, adaptive_rho=o.adaptive_rho,
            adaptive_rho_interval=o.adaptive_rho_interval,
            adaptive_rho_tolerance=o.adaptive_rho_tolerance,
            check_termination=o.check_termination, check_dualgap=o.check_dualgap,
            polishing=o.polish, scaling=o.scaling, warm_starting=s.warm_start != "none",
            **extra,
        )
        self._raw = getattr(self.osqp, "_solver", None)
        self._want_dual = want_dual

    def update(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, bounds: bool) -> None:
        """New linear cost ``q`` and, if ``bounds``, new ``l``/``u`` (P and A never change)."""
        if self._raw is not None:
            if bounds:
                self._raw.update_data_vec(q=q, l=lower, u=upper)
            else:
                self._raw.update_data_vec(q=q, l=None, u=None)
        elif bounds:
            self.osqp.update(q=q, l=lower, u=upper)
        else:
            self.osqp.update(q=q)

    def warm_start(self, x: np.ndarray, y: np.ndarray | None) -> None:
        """Start the next solve from primal ``x`` and dual ``y`` (``None``: OSQP's own)."""
        if self._raw is not None:
            self._raw.warm_start(x, y)
        else:
            self.osqp.warm_start(x=x, y=y)

    def solve(self) -> tuple[int, int, np.ndarray, np.ndarray | None]:
        """(status value, iterations, primal v, dual y or ``None``)."""
        if self._raw is not None:
            raw = self._raw
            raw.solve()
            info, sol = raw.info, raw.solution
            return info.status_val, info.iter, sol.x, sol.y if self._want_dual else None
        res = self.osqp.solve(raise_error=False)
        return res.info.status_val, res.info.iter, res.x, res.y

    def last_solution(self) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the last iterate (primal, dual), whatever its status."""
        if self._raw is not None:
            sol = self._raw.solution
            return np.array(sol.x, dtype=float), np.array(sol.y, dtype=float)
        res = self.osqp._derivative_cache.get("results")  # public API fallback
        if res is None:
            raise RuntimeError("no solve has run yet")
        return np.array(res.x, dtype=float), np.array(res.y, dtype=float)
