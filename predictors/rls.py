"""Exponentially weighted recursive least squares (RLS), the kernel of the linear predictors.

One object solves ``B`` independent problems of the same shape at once (``B = 1``
for correlated axes, ``B = d`` for independent axes).  Problem b has regressors
x ∈ ℝⁿ, targets y ∈ ℝ^q and weights W ∈ ℝ^{q×n}; after k samples W minimises

    J(W) = Σ_{i≤k} λ^{k−i} ‖y_i − W x_i‖² + λ^k δ ‖W − W₀‖²_F

with forgetting factor 0 < λ ≤ 1 and prior weight δ > 0 (``P₀ = I/δ``).  All q
outputs share the regressor, so one inverse correlation matrix P = Φ⁻¹ (n×n)
serves them: the Sherman–Morrison (matrix inversion lemma) form of Haykin,
*Adaptive Filter Theory* (2001), Table 10.1,

    π = P x,   κ = λ + xᵀπ,   k = π/κ,
    e = y − W x                   (a-priori error),
    W ← W + e kᵀ,
    P ← (P − k πᵀ)/λ,   P ← (P + Pᵀ)/2.

Cost per sample: ≈ B(2n² + 2qn) multiply-adds, no matrix inverse.

Numerical guards (counted in ``counts``):

``rls_reset``  κ ≤ 0 or non-finite P: P is reset to P₀ (weights kept);
``rls_bound``  wind-up: with λ < 1, directions that the data do not excite grow
               as λ^{−k}; when max diag P exceeds ``p_max`` P is scaled down to it.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

__all__ = ["RecursiveLeastSquares"]


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
        self.lam = float(forgetting_factor)
        self.delta = float(delta)
        self.p_max = float(p_max_factor) / self.delta
        self.counts = Counter() if counts is None else counts
        B, n, q = self.B, self.n, self.q
        self.W = np.zeros((B, q, n))
        self.P = np.empty((B, n, n))
        self._pi = np.empty((B, n, 1))
        self._kappa = np.empty((B, 1, 1))
        self._e = np.empty((B, q, 1))
        self._tmp = np.empty((B, n, n))
        self._wbuf = np.empty((B, q, n))
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
        """One RLS step with regressors ``x`` (B, n) and targets ``y`` (B, q)."""
        xc = x[:, :, None]
        pi, kappa, e, tmp = self._pi, self._kappa, self._e, self._tmp
        np.matmul(self.P, xc, out=pi)
        np.matmul(x[:, None, :], pi, out=kappa)
        kappa += self.lam
        if not (np.isfinite(kappa).all() and (kappa > 0.0).all()):
            self.counts["rls_reset"] += 1
            self.reset_covariance()
            return
        np.matmul(self.W, xc, out=e)
        np.subtract(y[:, :, None], e, out=e)  # a-priori error
        pi /= kappa  # gain k = π/κ (π is now k)
        # W += e kᵀ
        np.matmul(e, pi.transpose(0, 2, 1), out=self._wbuf)
        self.W += self._wbuf
        # P ← (P − k πᵀ)/λ with π = κ k, i.e. P − κ k kᵀ
        np.matmul(pi, pi.transpose(0, 2, 1), out=tmp)
        tmp *= kappa
        self.P -= tmp
        # symmetrise and divide by λ in one pass
        np.add(self.P, self.P.transpose(0, 2, 1), out=tmp)
        np.multiply(tmp, 0.5 / self.lam, out=self.P)
        peak = self._diag.max()
        if not np.isfinite(peak) or self._diag.min() <= 0.0:
            self.counts["rls_reset"] += 1
            self.reset_covariance()
        elif peak > self.p_max:
            self.counts["rls_bound"] += 1
            for b in range(self.B):
                top = self._diag[b].max()
                if top > self.p_max:
                    self.P[b] *= self.p_max / top
