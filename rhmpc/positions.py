"""Positions the controller and the simulated world share: below both, so that neither imports
the other.

- :class:`ArrayTruth`, the centred position of the point of interest (POI) at every tick, held in
  an array and read in windows (the loop's truth, and the exact reference's future);
- :func:`embed3`, positions of a motion of d ≤ 3 axes in the 3-D workspace (a 1-D motion moves
  along x).

Units: metres.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ArrayTruth", "embed3"]


class ArrayTruth:
    """Centred POI truth from an array of positions at ticks 0 … n − 1 (n, d), and the
    ``center`` [m] it was centred on (zero by default)."""

    def __init__(self, truth: np.ndarray, center: np.ndarray | None = None) -> None:
        self.truth = np.array(truth, dtype=float).reshape(len(truth), -1)
        self.n_ticks, self.dim = self.truth.shape
        self.center = np.zeros(self.dim) if center is None else np.asarray(center, dtype=float)
        if not np.all(np.isfinite(self.truth).any(axis=0)):
            raise ValueError("the truth has no finite sample on some axis")

    def window(self, i0: int, i1: int) -> np.ndarray:
        """The centred positions of ticks ``i0 … i1 − 1`` (i1 − i0, d) [m]."""
        return self.truth[i0:i1]


def embed3(p: np.ndarray) -> np.ndarray:
    """(n, d) positions with d ≤ 3 as (n, 3), missing axes zero (1-D motion along x)."""
    p = np.atleast_2d(p)
    if p.shape[1] == 3:
        return p
    out = np.zeros((p.shape[0], 3))
    out[:, : p.shape[1]] = p
    return out
