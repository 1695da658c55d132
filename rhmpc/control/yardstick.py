"""The yardstick of every timing: the bare gain tick g, timed in the same run as what it measures.

Timings of the controller (``rhmpc bench``, ``rhmpc simulate``) are reported as multiples of
the time of :class:`GainTick` measured in the same minutes, so that they compare across machines
and loads.
"""

from __future__ import annotations

import math

import numpy as np

from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.offset import OutputOffset


class QPParameters:
    """p = [x; r_1..r_N; u_{−1}; d] in a preallocated buffer, d by forward kinematics as in the
    controller (:class:`rhmpc.control.offset.OutputOffset`), so both references solve the QP the
    controller solves."""

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


class GainTick:
    """Reference 1: the precomputed unconstrained gain, clipped (same parameter handling)."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        qp = mpc.qp
        self._params = QPParameters(mpc)
        self._K, self._k0 = qp.gain, qp.gain0
        self._lo, self._hi = -qp.u_max, qp.u_max

    def __call__(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        if not self._params.fill(x, ref, u_prev):
            return np.zeros_like(self._k0)
        u = self._K @ self._params.p
        u += self._k0
        np.maximum(u, self._lo, out=u)
        return np.minimum(u, self._hi, out=u)


