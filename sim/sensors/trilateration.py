r"""3-D position from ranges to crystals at known positions (trilateration).

The instrument's software solves, per sample, the nonlinear least-squares problem

.. math::

    \hat x = \arg\min_x \sum_i \bigl(\lVert x - b_i \rVert - r_i\bigr)^2,

:math:`b_i` the reference crystals, :math:`r_i` the measured ranges (Ratcliffe et al. 1995;
Sonometrics SonoSOFT). :func:`trilaterate` starts from the linearised closed form (the spheres
minus the first one are planes,
:math:`2 (b_i - b_0)^\mathsf{T} x = \lVert b_i \rVert^2 - \lVert b_0 \rVert^2 - r_i^2 + r_0^2`)
and polishes it with Gauss–Newton steps, vectorised over the samples. For coplanar crystals (the
paper's base) the linear system fixes only the in-plane coordinates u; the normal one follows
from the spheres, :math:`h^2 = \operatorname{mean}_i \bigl(r_i^2 - \lVert u - b_i \rVert^2\bigr)`,
on the side of the plane where the POI is.
"""

from __future__ import annotations

import numpy as np


def _closed_form(anchors: np.ndarray, ranges: np.ndarray, side: np.ndarray) -> np.ndarray:
    """Linearised trilateration of every row of ``ranges`` (n, m) → (n, 3)."""
    center = anchors.mean(axis=0)
    _, s, vt = np.linalg.svd(anchors - center)
    planar = s[2] <= 1e-9 * s[0]
    basis = vt[:2] if planar else vt
    b = (anchors - center) @ basis.T  # anchors in the local frame (m, k)
    a = 2.0 * (b[1:] - b[0])
    sq = np.sum(b**2, axis=1)
    rhs = (sq[1:] - sq[0])[None, :] - ranges[:, 1:] ** 2 + ranges[:, :1] ** 2
    u = np.linalg.lstsq(a, rhs.T, rcond=None)[0].T  # (n, k)
    x = center + u @ basis
    if planar:
        normal = vt[2] if float(np.dot(side - center, vt[2])) >= 0 else -vt[2]
        d2 = ranges**2 - np.sum((u[:, None, :] - b[None, :, :]) ** 2, axis=2)
        x = x + np.sqrt(np.maximum(d2.mean(axis=1), 0.0))[:, None] * normal
    return x


def trilaterate(anchors: np.ndarray, ranges: np.ndarray, side: np.ndarray | None = None,
                iterations: int = 3) -> np.ndarray:
    """Least-squares positions from ranges (closed form, then Gauss–Newton).

    Parameters
    ----------
    anchors : ndarray, shape (m, 3)
        Reference crystal positions b_i [m], m ≥ 4 (not all on one line).
    ranges : ndarray, shape (n, m)
        Measured ranges r_i per sample [m]; a row with a NaN gives a NaN position.
    side : ndarray, shape (3,), optional
        A point on the POI's side of the plane, for coplanar anchors (default: +normal).
    iterations : int
        Gauss–Newton steps Δx = −(JᵀJ)⁻¹Jᵀf, f_i = ‖x − b_i‖ − r_i, J_i = (x − b_i)ᵀ/‖x − b_i‖.

    Returns
    -------
    ndarray, shape (n, 3)
        x̂ [m].
    """
    anchors = np.asarray(anchors, dtype=float)
    ranges = np.atleast_2d(np.asarray(ranges, dtype=float))
    if anchors.ndim != 2 or anchors.shape[1] != 3 or anchors.shape[0] < 4:
        raise ValueError("trilateration needs ≥ 4 anchors of shape (m, 3)")
    if ranges.shape[1] != anchors.shape[0]:
        raise ValueError("ranges must have one column per anchor")
    side = anchors.mean(axis=0) + np.array([0, 0, 1.0]) if side is None else np.asarray(side)
    ok = np.isfinite(ranges).all(axis=1)
    out = np.full((ranges.shape[0], 3), np.nan)
    if not ok.any():
        return out
    r = ranges[ok]
    x = _closed_form(anchors, r, side)
    for _ in range(iterations):
        diff = x[:, None, :] - anchors[None, :, :]  # (n, m, 3)
        dist = np.linalg.norm(diff, axis=2)
        jac = diff / np.maximum(dist, 1e-12)[:, :, None]
        f = dist - r
        jtj = np.einsum("nmi,nmj->nij", jac, jac)
        jtf = np.einsum("nmi,nm->ni", jac, f)
        x = x - np.linalg.solve(jtj, jtf[:, :, None])[:, :, 0]
    out[ok] = x
    return out


def dilution(anchors: np.ndarray, x: np.ndarray) -> np.ndarray:
    """σ_axis / σ_range at ``x``: √diag((JᵀJ)⁻¹) of the linearised least squares [-].

    For independent range errors of standard deviation σ_r, the position error per axis has
    standard deviation σ_r·√diag((JᵀJ)⁻¹), J_i the unit vector from b_i to x (the geometric
    dilution of precision).
    """
    diff = np.asarray(x, dtype=float)[None, :] - np.asarray(anchors, dtype=float)
    jac = diff / np.linalg.norm(diff, axis=1, keepdims=True)
    return np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
