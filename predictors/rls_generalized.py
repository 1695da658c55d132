"""Generalized linear predictor: one RLS weight block per horizon point (Tuna et al. 2013, §VI).

Eq. (9): V [z_n; …; z_{n−N+1}] = [ẑ_{n+1}; …; ẑ_{n+M}], with V = [CΦ_{0,1}; …; CΦ_{0,M}]
(eq. 11) and each block CΦ_{0,i} fitted independently.  Assuming slowly varying
statistics, V is learnt from the M-step-delayed problem (eq. 10), in which every
quantity has been observed:

    V [z_{n−M}; …; z_{n−M−N+1}] ≈ [z_{n−M+1}; …; z_n].

All M blocks share the regressor, hence one inverse correlation matrix P: an
update costs one Sherman–Morrison step with n = N·d regressors and q = M·d outputs,
≈ 2(Nd)² + 2(Nd)(Md) multiply-adds (N = 10, d = 3, M = 4: ≈ 2.5k), instead of M
separate RLS predictors.  A forecast of K ≤ M points is one (Md × Nd) product.

Forecasts beyond M points are chained: the M forecasts are pushed as if observed
and V is applied again (an extension; Tuna use K = M).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.predictors.delay_line import DelayLinePredictor, TappedDelayLine
from rhmpc.predictors.rls_one_step import RLSCommon, make_rls

__all__ = ["GeneralizedRLS", "GeneralizedSettings"]


@dataclass(frozen=True)
class GeneralizedSettings(RLSCommon):
    """Generalized predictor settings (defaults: Tuna et al. 2013, §VIII-B).

    Attributes
    ----------
    order : int
        N, past samples in the regressor [-]; 10 in Tuna's experiments.
    points : int
        M, horizon points with their own weight block [-]; 4 (at 7.5 ms, 30 ms ≥ 25 ms).
    """

    order: int = 10
    points: int = 4

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("order", "points"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")


class GeneralizedRLS(DelayLinePredictor):
    """Generalized adaptive-filter predictor (Tuna §VI, eqs. 9–11)."""

    Settings = GeneralizedSettings

    def _allocate(self, d: int) -> None:
        s = self.settings
        N, M = s.order, s.points
        batch, n, q = (1, N * d, M * d) if s.correlated else (d, N, M)
        self.rls = make_rls(s, batch, n, q, self.unit, self.counts)
        # target rows are newest-first: block j predicts M − j steps ahead
        if s.init == "hold":
            if s.correlated:
                for j in range(M):
                    self.rls.W[0, j * d : (j + 1) * d, :d] = np.eye(d)
            else:
                self.rls.W[:, :, 0] = 1.0
        self.line = TappedDelayLine(N + M, d)

    def _update(self, z: np.ndarray) -> None:
        s = self.settings
        N, M = s.order, s.points
        line = self.line
        self._push(z)
        if line.real_run >= N + M:
            past, recent = line.buf[M : M + N], line.buf[:M]
            if s.correlated:
                self.rls.update(past.reshape(1, -1), recent.reshape(1, -1))
            else:
                self.rls.update(past.T, recent.T)
        self.ready = line.filled >= N

    def _block(self, past: np.ndarray) -> np.ndarray:
        """[ẑ_{n+1}; …; ẑ_{n+M}] as (M, d) from the newest-first block ``past`` (N, d)."""
        s, d = self.settings, self.d
        if s.correlated:
            out = (self.rls.W[0] @ past.reshape(-1)).reshape(s.points, d)
        else:
            out = np.einsum("bji,ib->jb", self.rls.W, past)
        return out[::-1]

    def _next(self, past: np.ndarray) -> np.ndarray:
        """ẑ_{n+1}: the first block of :meth:`_block`."""
        return self._block(past)[0]

    def _predict(self, steps: int) -> np.ndarray:
        N, M = self.settings.order, self.settings.points
        first = self._block(self.line.buf[:N])
        if steps <= M:
            return first[:steps].copy()
        blocks = -(-steps // M)
        out = np.empty((blocks * M, self.d))
        out[:M] = first
        # newest first: the forecasts so far (reversed), then the delay line's N rows
        hist = np.empty(((blocks - 1) * M + N, self.d))
        hist[-N:] = self.line.buf[:N]
        for b in range(1, blocks):
            top = (blocks - 1 - b) * M  # block b − 1's forecasts, then the older rows
            hist[top : top + M] = out[(b - 1) * M : b * M][::-1]
            out[b * M : (b + 1) * M] = self._block(hist[top : top + N])
        return out[:steps]

    @property
    def weights(self) -> np.ndarray:
        """V, rows [ẑ_{n+1}; …; ẑ_{n+M}]: (M·d, N·d) correlated, (d, M, N) independent."""
        W = self.rls.W
        if self.settings.correlated:
            d, M = self.d, self.settings.points
            return W[0].reshape(M, d, -1)[::-1].reshape(M * d, -1).copy()
        return W[:, ::-1, :].copy()
