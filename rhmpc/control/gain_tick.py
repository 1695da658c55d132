"""The gain tick: the yardstick that controller timings are stated against (×g).

It is the floor of what any controller in Python costs here: the MPC's parameter handling plus
its precomputed unconstrained gain, clipped, ``u = clip(K p + k0, −τ_max, τ_max)`` with
``p = [x; r; u_prev]``. ``rhmpc bench`` and ``rhmpc simulate`` time it in the same run as the
controller, so that their ratios hold on a loaded machine.
"""

from __future__ import annotations

import math

import numpy as np

from rhmpc.control.mpc import RecedingHorizonMPC


class GainTick:
    """Reference 1: the precomputed unconstrained gain, clipped (same parameter handling)."""

    def __init__(self, mpc: RecedingHorizonMPC) -> None:
        qp = mpc.qp
        self._p = np.zeros(qp.npar)
        self._nx, self._nr = qp.nx, qp.N * qp.ny
        self._K, self._k0 = qp.gain, qp.gain0
        self._lo, self._hi = -qp.u_max, qp.u_max

    def __call__(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        p = self._p
        p[: self._nx] = x
        p[self._nx : self._nx + self._nr] = ref.reshape(-1)
        p[self._nx + self._nr :] = u_prev
        if not math.isfinite(p.sum()):
            return np.zeros_like(self._k0)
        u = self._K @ p
        u += self._k0
        np.maximum(u, self._lo, out=u)
        return np.minimum(u, self._hi, out=u)
