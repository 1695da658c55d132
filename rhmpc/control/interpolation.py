"""Piecewise-quadratic (3-node Lagrange) interpolation of forecast nodes, and windows of
points: the arithmetic of :mod:`rhmpc.control.reference`.

With node coordinates ``s`` in predictor periods, the window ``m, m+1, m+2`` (``m =
clamp(⌊s⌋, 0, K − 3)`` for K nodes) and ``u = s − m``::

    r(s) = ½(u−1)(u−2)·z_m − u(u−2)·z_{m+1} + ½u(u−1)·z_{m+2}
"""

from __future__ import annotations

import numpy as np

__all__ = ["interpolation_matrix", "quadratic_weights", "windows"]


#: The three Lagrange weights on nodes m, m+1, m+2 as polynomials in u = s − m, in the basis
#: (u², u, 1): ½(u−1)(u−2), −u(u−2), ½u(u−1).
_LAGRANGE = np.array([[0.5, -1.5, 1.0], [-1.0, 2.0, 0.0], [0.5, -0.5, 0.0]])


def _window_weights(s: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """``m`` (n,) and the weights as rows, shape (3, n)."""
    if n_nodes < 3:
        raise ValueError(f"quadratic interpolation needs at least 3 nodes, got {n_nodes}")
    m = np.floor(s)
    np.minimum(m, float(n_nodes - 3), out=m)
    np.maximum(m, 0.0, out=m)
    basis = np.ones((3, s.shape[0]))
    u = np.subtract(s, m, out=basis[1])
    np.multiply(u, u, out=basis[0])
    return m.astype(np.intp), _LAGRANGE @ basis


def quadratic_weights(s: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Window start ``m`` and the three Lagrange weights for node coordinates ``s`` (in periods).

    Returns ``m`` (n,) and ``w`` (n, 3) with r(s) = Σ_j w[:, j] · node[m + j].
    """
    m, w = _window_weights(s, n_nodes)
    return m, w.T


def interpolation_matrix(s: np.ndarray, n_nodes: int) -> np.ndarray:
    """W (n, n_nodes) with W @ nodes = the piecewise-quadratic interpolation at ``s``."""
    m, w = _window_weights(s, n_nodes)
    n = s.shape[0]
    W = np.zeros(n * n_nodes)
    m += np.arange(0, n * n_nodes, n_nodes)  # flat index of each row's first node
    W[m] = w[0]
    m += 1
    W[m] = w[1]
    m += 1
    W[m] = w[2]
    return W.reshape(n, n_nodes)


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
