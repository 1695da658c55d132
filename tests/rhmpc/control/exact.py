"""The tests' references of the controller: its QP's vectors and unconstrained input rebuilt from
the QP's data, and an exact level 3 (the QP solved by DAQP in OSQP's place).

DAQP (dual active set; Arnström, Bemporad & Axehill, IEEE TAC 67(8), 2022) solves the QP
exactly, hot-started from its last working set, in a few changes of its active set where ADMM
needs hundreds of iterations: with it in the controller's place of OSQP, a test sees what the
controller does with every QP answered exactly (the envelope binding, the cascade's decisions
against an exact solve). DAQP's multipliers follow OSQP's sign convention (positive on an
active upper bound), checked by the KKT tests.
"""

from __future__ import annotations

import dataclasses

import daqp
import numpy as np
import osqp

from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.offset import OutputOffset
from rhmpc.control.settings import MPCSettings

_SOLVED = int(osqp.SolverStatus.OSQP_SOLVED)
#: DAQP exit flags as the OSQP statuses of the same meaning.
_DAQP_STATUS = {-1: int(osqp.SolverStatus.OSQP_PRIMAL_INFEASIBLE),
                -3: int(osqp.SolverStatus.OSQP_DUAL_INFEASIBLE),
                -4: int(osqp.SolverStatus.OSQP_MAX_ITER_REACHED),
                -5: int(osqp.SolverStatus.OSQP_NON_CVX)}


class DAQPLevel3:
    """The controller's QP in DAQP: the first nv rows of A (identity) are its simple bounds,
    the envelope rows its general constraints; at most one active-set change per row."""

    def __init__(self, qp) -> None:
        self._model = daqp.Model()
        self._A = np.ascontiguousarray(qp.A[qp.nv:])
        self._bu, self._bl = np.minimum(qp.u0, 1e30), np.maximum(qp.l0, -1e30)  # DAQP's inf
        flag, _ = self._model.setup(qp.P, qp.f0.copy(), self._A, self._bu, self._bl)
        assert flag >= 0, f"DAQP setup failed with exit flag {flag}"
        self._model.settings = {"iter_limit": int(qp.A.shape[0])}
        self.x, self.y = np.zeros(qp.nv), np.zeros(qp.A.shape[0])

    def update(self, q, lower, upper, bounds: bool) -> None:
        if bounds:
            np.minimum(upper, 1e30, out=self._bu)
            np.maximum(lower, -1e30, out=self._bl)
            self._model.update(f=q, bupper=self._bu, blower=self._bl)
        else:
            self._model.update(f=q)

    def warm_start(self, x, y) -> None:
        """DAQP hot-starts from its own last working set."""

    def solve(self) -> tuple[int, int, np.ndarray]:
        x, _, flag, info = self._model.solve()
        self.x, self.y = x, np.asarray(info["lam"], dtype=float)
        return (_SOLVED if flag >= 1 else _DAQP_STATUS.get(flag, 10_000 + flag)), \
            info["iterations"], x

    def last_solution(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x.copy(), self.y.copy()


def exact_mpc(arm, settings: MPCSettings | None = None) -> RecedingHorizonMPC:
    """The controller with DAQP as its level 3 (and level 2 uncapped, so that every tick the
    box QP does not settle reaches the exact solve)."""
    settings = dataclasses.replace(settings or MPCSettings(), box_max_iter=10_000)
    mpc = RecedingHorizonMPC(arm, settings)
    mpc._solver = DAQPLevel3(mpc.qp)
    return mpc


class EveryTick(RecedingHorizonMPC):
    """The controller with its QP given to level 3 on every tick (levels 1 and 2 skipped), no
    back-off: a plain solve of the same QP, to hold the cascade to."""

    def __init__(self, arm, settings: MPCSettings | None = None) -> None:
        super().__init__(arm, dataclasses.replace(settings or MPCSettings(),
                                                  backoff_max_ticks=0))

    def _level1(self) -> bool:
        return False

    def _box_solved(self) -> bool:
        return False


def params(mpc: RecedingHorizonMPC, x, ref, u_prev=None) -> np.ndarray:
    """p = [x; r_1..r_N; u_{−1}; d(x)] of the QP the controller solves (u_{−1} defaults to its
    last output; d the output offset, 0 without ``offset_correction``)."""
    x = np.asarray(x, dtype=float)
    d = OutputOffset(mpc.arm)(x) if mpc.settings.offset_correction else None
    return mpc.qp.params(x, np.asarray(ref, dtype=float),
                         mpc.u_prev if u_prev is None else np.asarray(u_prev, dtype=float), d)


def qp_vectors(mpc: RecedingHorizonMPC, x, ref, u_prev=None):
    """(q, l, u) of the QP the controller would solve for ``x``, ``ref`` (P, A: ``mpc.qp``)."""
    p = params(mpc, x, ref, u_prev)
    return (mpc.qp.q(p), *mpc.qp.bounds(p))


def unconstrained(mpc: RecedingHorizonMPC, x, ref, u_prev=None) -> np.ndarray:
    """The first input of the unconstrained minimiser, not clipped [N·m] (the LQ fallback)."""
    return mpc.qp.gain @ params(mpc, x, ref, u_prev) + mpc.qp.gain0
