"""The yardstick of every timing: the bare gain tick g, timed in the same run as what it measures.

Timings of the controller (``rhmpc bench``, ``rhmpc simulate``) are reported as multiples of
the time of :class:`GainTick` measured in the same minutes, so that they compare across machines
and loads. g is a fixed piece of work — the unconstrained MPC's gain applied to the parameters —
that no feature of the controller grows: the output offset, the envelope and the clipping are
the controller's, not the yardstick's. ``rhmpc bench`` also times the same mat-vec written in
plain NumPy (:func:`numpy_gain_step`), so that a reader sees g for what it is. g is timed as the
least of three consecutive calls (:func:`rhmpc.sim.loop.metrics.warm_ns`): the fixed work itself,
not the state that the work around it leaves the caches in, which differs between ``rhmpc
bench`` (an MPC, an exact solve and an OSQP solve each tick) and the closed loop.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rhmpc.control.mpc import RecedingHorizonMPC


class GainTick:
    """g: u = K p + k₀ with p = [x; r_1..r_N; u_{−1}] assembled in a preallocated buffer.

    K (nu × (nx + N·ny + nu)) and k₀ are the unconstrained MPC's precomputed gain on those
    parameters (:attr:`CondensedQP.gain`, its offset columns left out): the floor of what any
    controller in Python costs here, a few NumPy calls.
    """

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        qp = mpc.qp
        self._nx, self._nr = qp.nx, qp.N * qp.ny
        n = self._nx + self._nr + qp.nu
        self._K = np.ascontiguousarray(qp.gain[:, :n])
        self._k0 = qp.gain0.copy()
        self._p = np.zeros(n)
        self._x, self._r, self._u = (self._p[: self._nx], self._p[self._nx : self._nx + self._nr],
                                     self._p[self._nx + self._nr :])

    def __call__(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        self._x[:] = x
        self._r[:] = ref.reshape(-1)
        self._u[:] = u_prev
        u = self._K @ self._p
        u += self._k0
        return u


def numpy_gain_step(K: np.ndarray, k0: np.ndarray) -> Callable[..., np.ndarray]:
    """The same work in plain NumPy: ``K @ concatenate((x, r.ravel(), u_prev)) + k0``."""

    def step(x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        return K @ np.concatenate((x, ref.ravel(), u_prev)) + k0

    return step
