"""Exponentially weighted recursive least squares (RLS), the kernel of the linear predictors.

One object solves ``B`` independent problems of the same shape at once (``B = 1``
for correlated axes, ``B = d`` for independent axes).  Problem b has regressors
x ∈ ℝⁿ, targets y ∈ ℝ^q and weights W ∈ ℝ^{q×n}; after k samples W minimises::

    J(W) = Σ_{i≤k} λ^{k−i} ‖y_i − W x_i‖² + λ^k δ ‖W − W₀‖²_F

with forgetting factor 0 < λ ≤ 1 and prior weight δ > 0 (``P₀ = I/δ``).  All q
outputs share the regressor, so one inverse correlation matrix P = Φ⁻¹ (n×n)
serves them: the Sherman–Morrison (matrix inversion lemma) form of Haykin,
*Adaptive Filter Theory* (2001), Table 10.1::

    π = P x,   κ = λ + xᵀπ,   k = π/κ,
    e = y − W x                   (a-priori error),
    W ← W + e kᵀ,
    P ← (P − k πᵀ)/λ,   P ← (P + Pᵀ)/2.

Cost per sample: ≈ B(2n² + 2qn) multiply-adds, no matrix inverse.

Numerical guards (counted in ``counts``):

``rls_reset``
    κ ≤ 0 or non-finite P: P is reset to P₀ (weights kept);
``rls_bound``
    wind-up: with λ < 1, directions that the data do not excite grow as λ^{−k}; diagonal
    entries above ``p_max`` are brought back to it by the congruence P ← D P D (D diagonal
    ≤ 1), which keeps P positive definite and leaves the excited coordinates alone.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
from scipy.linalg.blas import dger, dsymv, dsyr

__all__ = ["RecursiveLeastSquares"]


#: The most memory an RLS's covariances P (batch × n × n) may take [bytes]: 512 MiB.
RLS_MAX_BYTES = 2**29


class RecursiveLeastSquares:
    """B independent RLS problems with n regressors and q outputs each.

    Parameters
    ----------
    batch, n, q : int
        Number of problems, regressors per problem, outputs per problem.
    forgetting_factor : float
        λ ∈ (0, 1]; effective memory ≈ 1/(1 − λ) samples.
    delta : float
        Prior weight δ > 0 in data units² (``P₀ = I/δ``).
    p_max_factor : float
        Wind-up bound: max diag P ≤ p_max_factor/δ.
    counts : Counter, optional
        Where guard events are counted (shared with the owning predictor).
    """

    def __init__(
        self,
        batch: int,
        n: int,
        q: int,
        forgetting_factor: float,
        delta: float,
        p_max_factor: float = 10.0,
        counts: Counter | None = None,
    ) -> None:
        self.B, self.n, self.q = int(batch), int(n), int(q)
        size = 8 * self.B * self.n * self.n
        if size > RLS_MAX_BYTES:  # P has n² entries per problem
            largest = int((RLS_MAX_BYTES / (8 * self.B)) ** 0.5)
            raise ValueError(f"a regressor of {self.n} values (the order times the values per "
                             f"sample) needs {size / 2**30:.3g} GiB for the RLS's covariance; "
                             f"at most {largest} values fit in {RLS_MAX_BYTES // 2**20} MiB: "
                             "lower the order")
        self.lam = float(forgetting_factor)
        self.delta = float(delta)
        self.p_max = float(p_max_factor) / self.delta
        self.counts = Counter() if counts is None else counts
        B, n, q = self.B, self.n, self.q
        self.W = np.zeros((B, q, n))
        self.P = np.empty((B, n, n))
        self._pi = np.empty((B, n))
        self._PT = [self.P[b].T for b in range(B)]  # Fortran-ordered views for BLAS
        self._WT = [self.W[b].T for b in range(B)]
        self._diag = np.einsum("bii->bi", self.P)  # a writable view of the diagonals
        self.reset_covariance()

    def reset_covariance(self, b: int | None = None) -> None:
        """P ← P₀ = I/δ (for problem ``b``, or all)."""
        sel = slice(None) if b is None else b
        self.P[sel] = 0.0
        np.einsum("...ii->...i", self.P[sel])[...] = 1.0 / self.delta

    def predict(self, x: np.ndarray) -> np.ndarray:
        """W x for regressors ``x`` of shape (B, n); returns (B, q)."""
        return np.matmul(self.W, x[:, :, None])[:, :, 0]

    def update(self, x: np.ndarray, y: np.ndarray) -> None:
        """One RLS step with regressors ``x`` (B, n) and targets ``y`` (B, q).

        BLAS level-2 calls on preallocated storage: P is kept exactly symmetric by
        updating one triangle (``dsyr``) and reading it with ``dsymv``.
        """
        lam = self.lam
        for b in range(self.B):
            xb = x[b]
            Pb = self._PT[b]  # Fortran view of P[b]; its upper triangle is authoritative
            pi = dsymv(1.0, Pb, xb, y=self._pi[b], overwrite_y=1)
            kappa = lam + float(np.dot(xb, pi))
            if not (kappa > 0.0 and math.isfinite(kappa)):
                self.counts["rls_reset"] += 1
                self.reset_covariance(b)
                continue
            e = y[b] - np.dot(self.W[b], xb)  # a-priori error
            dger(1.0 / kappa, pi, e, a=self._WT[b], overwrite_a=1)  # W += e kᵀ, k = π/κ
            dsyr(-1.0 / kappa, pi, a=Pb, overwrite_a=1)  # P −= π πᵀ/κ
            if lam != 1.0:
                self.P[b] *= 1.0 / lam
            diag = self._diag[b]
            peak = diag[diag.argmax()]  # argmax, argmin: a quarter of max()'s cost; NaN wins
            if not (math.isfinite(peak) and diag[diag.argmin()] > 0.0):
                self.counts["rls_reset"] += 1
                self.reset_covariance(b)
            elif (
                peak > self.p_max
            ):  # P ← D P D, D = diag(min(1, √(p_max/P_ii))): congruent, stays PD
                self.counts["rls_bound"] += 1
                scale = np.sqrt(np.minimum(1.0, self.p_max / diag))
                self.P[b] *= np.multiply.outer(scale, scale)

    def covariance(self, b: int = 0) -> np.ndarray:
        """The full symmetric P of problem ``b`` (a copy)."""
        return np.triu(self._PT[b]) + np.triu(self._PT[b], 1).T
