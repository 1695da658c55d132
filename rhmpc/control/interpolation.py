"""Piecewise-cubic (4-node Lagrange) interpolation of forecast nodes, and windows of points:
the arithmetic of :mod:`rhmpc.control.reference`.

With node coordinates ``s`` in predictor periods, the window ``m … m+3`` around the interval of
s (``m = clip(⌊s⌋ − 1, 0, K − 4)`` for K nodes) and ``u = s − m``::

    r(s) = −(u−1)(u−2)(u−3)/6·z_m + u(u−2)(u−3)/2·z_{m+1}
           − u(u−1)(u−3)/2·z_{m+2} + u(u−1)(u−2)/6·z_{m+3}
"""

from __future__ import annotations

import numpy as np

__all__ = ["WINDOW", "interpolation_matrix", "lagrange_weights", "windows"]


#: Nodes of the interpolation's window (cubic: 4).
WINDOW = 4
#: The four Lagrange weights on nodes m … m+3 as polynomials in u = s − m, in the basis
#: (u³, u², u, 1): −(u−1)(u−2)(u−3)/6, u(u−2)(u−3)/2, −u(u−1)(u−3)/2, u(u−1)(u−2)/6.
_LAGRANGE = np.array([[-1 / 6, 1.0, -11 / 6, 1.0], [0.5, -2.5, 3.0, 0.0],
                      [-0.5, 2.0, -1.5, 0.0], [1 / 6, -0.5, 1 / 3, 0.0]])


def lagrange_weights(s: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Window start ``m`` and the four Lagrange weights for node coordinates ``s`` (in periods).

    Returns ``m`` (n,) and ``w`` (n, 4) with r(s) = Σ_j w[:, j] · node[m + j], the window
    m = clip(⌊s⌋ − 1, 0, n_nodes − 4) (module docstring).
    """
    if n_nodes < WINDOW:
        raise ValueError(f"cubic interpolation needs at least {WINDOW} nodes, got {n_nodes}")
    m = np.clip(np.floor(s) - 1.0, 0.0, float(n_nodes - WINDOW))
    u = s - m
    basis = np.stack([u**3, u**2, u, np.ones_like(u)])
    return m.astype(np.intp), (_LAGRANGE @ basis).T


def interpolation_matrix(s: np.ndarray, n_nodes: int) -> np.ndarray:
    """W (n, n_nodes) with W @ nodes = the piecewise-cubic interpolation at ``s``."""
    m, w = lagrange_weights(s, n_nodes)
    W = np.zeros((s.shape[0], n_nodes))
    rows = np.arange(s.shape[0])
    for j in range(WINDOW):
        W[rows, m + j] = w[:, j]
    return W


def windows(points: np.ndarray, first: int, count: int, N: int) -> np.ndarray:
    """Rows ``first + k … first + k + N − 1`` of ``points`` (n, d) for k < count, as one
    read-only (count, N, d) array: a view of overlapping windows, or a copy when it runs past
    the last row (the last window is then repeated: a skipped refresh holds its points).
    ``points`` must hold at least N rows."""
    last = points.shape[0] - N
    if last < 0:
        raise ValueError(f"{points.shape[0]} points cannot make windows of {N}")
    if first + count - 1 > last or not points.flags.c_contiguous:
        starts = np.minimum(np.arange(first, first + count), last)
        out = points[starts[:, None] + np.arange(N)]
    else:
        row = points.strides[0]
        out = np.ndarray((count, N, points.shape[1]), points.dtype, points, first * row,
                         (row, row, points.strides[1]))
    out.flags.writeable = False
    return out
