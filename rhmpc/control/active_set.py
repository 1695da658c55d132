"""DAQP, the exact dual active-set QP solver, behind the MPC's solver interface.

The controller talks to its solver in OSQP's terms (status values, primal ``x``, multipliers
``y`` of ``l ≤ A v ≤ u``); this adapter gives DAQP the same shape. DAQP's multipliers follow
OSQP's sign convention (positive on an active upper bound), checked by the KKT tests.
"""

from __future__ import annotations

import daqp
import numpy as np
import osqp

from rhmpc.control.qp import CondensedQP

_SOLVED = int(osqp.SolverStatus.OSQP_SOLVED)
#: DAQP exit flags as the OSQP statuses of the same meaning.
_DAQP_STATUS = {
    -1: int(osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE),
    -3: int(osqp.SolverStatus.OSQP_DUAL_INFEASIBLE),
    -4: int(osqp.SolverStatus.OSQP_MAX_ITER_REACHED),
    -5: int(osqp.SolverStatus.OSQP_NON_CVX),
}


class ActiveSetSolver:
    """The same QP solved by DAQP (dual active set; Arnström, Bemporad & Axehill, IEEE TAC 67(8),
    2022): exact, hot-started from the last working set, at most ``iter_limit`` active-set
    changes. The first nv rows of A (identity) are its simple bounds; the envelope rows its
    general constraints."""

    def __init__(self, qp: CondensedQP, iter_limit: int) -> None:
        self._model = daqp.Model()
        self._A = np.ascontiguousarray(qp.A[qp.nv:])
        self._bu = np.minimum(qp.u0, 1e30)  # DAQP's infinity
        self._bl = np.maximum(qp.l0, -1e30)
        flag, _ = self._model.setup(qp.P, qp.f0.copy(), self._A, self._bu, self._bl)
        if flag < 0:
            raise ValueError(f"DAQP setup failed with exit flag {flag}")
        self._model.settings = {"iter_limit": int(iter_limit)}
        self.x = np.zeros(qp.nv)
        self.y = np.zeros(qp.A.shape[0])

    def update(self, q: np.ndarray, lower: np.ndarray, upper: np.ndarray, bounds: bool) -> None:
        if bounds:
            np.minimum(upper, 1e30, out=self._bu)
            np.maximum(lower, -1e30, out=self._bl)
            self._model.update(f=q, bupper=self._bu, blower=self._bl)
        else:
            self._model.update(f=q)

    def solve(self) -> tuple[int, int, np.ndarray, np.ndarray]:
        """(status as an OSQP status value, iterations, primal v, multipliers y)."""
        x, _, flag, info = self._model.solve()
        self.x, self.y = x, np.asarray(info["lam"], dtype=float)
        return (_SOLVED if flag >= 1 else _DAQP_STATUS.get(flag, 10_000 + flag)), info[
            "iterations"], x, self.y
