"""One-step RLS predictor of a vector autoregressive (VAR) model (Tuna et al. 2013, §V).

Model (eq. 1): z_k = Σ_{i=1}^{N} A_i z_{k−i} + γ_k, W = [A_1 … A_N] (eq. 6).
RLS fits W to the one-step problem [z_{n−1}; …; z_{n−N}] ↦ z_n (eq. 5) with
exponential forgetting λ, and the horizon is the iterated one-step forecast (eqs. 7–8):

    ẑ_{n+k} = W [ẑ_{n+k−1}; …; ẑ_{n+k−N}],   with ẑ_j = z_j for j ≤ n.

Cost per update: one RLS step with n = N·d regressors and d outputs when the axes
are correlated (3×3 matrices A_i), or d RLS steps with n = N and one output when
they are independent (§VII-A): ≈ 2(Nd)² + 2N d² resp. d(2N² + 2N) multiply-adds.
A forecast of K points costs K matrix–vector products.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.predictors.base import PredictorSettings
from rhmpc.predictors.delay_line import DelayLinePredictor, TappedDelayLine
from rhmpc.predictors.rls import RecursiveLeastSquares

__all__ = ["OneStepRLS", "OneStepSettings"]

_INITS = ("hold", "zeros")


@dataclass(frozen=True)
class RLSCommon(PredictorSettings):
    """Settings shared by the RLS predictors.

    Attributes
    ----------
    forgetting_factor : float
        λ ∈ (0, 1] [-], per sample.  Tuna et al. give no value; 0.999 is an
        effective memory of 1/(1 − λ) = 1000 samples (7.5 s at 133 Hz).
    correlated : bool
        True: one RLS problem with d×d weight matrices (Tuna's "correlated"
        predictor); False: an independent scalar filter per axis (§VII-A).
    delta : float
        Prior weight δ [m²]; P₀ = I/δ in data units (δ/unit²).  Small against the
        signal power so that the prior W₀ is forgotten within ~N samples.
    init : str
        W₀: ``"hold"`` (ẑ_{n+1} = z_n until data say otherwise) or ``"zeros"``.
    unit : float or None
        Metres per data unit (1.0 for samples in m, 1e-3 for mm); ``None``: inferred.
    p_max_factor : float
        Wind-up bound: max diag P ≤ p_max_factor · P₀ [-].
    """

    forgetting_factor: float = 0.999
    correlated: bool = True
    delta: float = 1e-8
    init: str = "hold"
    unit: float | None = None
    p_max_factor: float = 10.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 < self.forgetting_factor <= 1.0:
            raise ValueError(f"forgetting_factor must be in (0, 1], got {self.forgetting_factor}")
        if not self.delta > 0.0:
            raise ValueError(f"delta must be > 0 [m²], got {self.delta}")
        if self.init not in _INITS:
            raise ValueError(f"init must be one of {_INITS}, got {self.init!r}")
        if not self.p_max_factor >= 1.0:
            raise ValueError(f"p_max_factor must be >= 1, got {self.p_max_factor}")


@dataclass(frozen=True)
class OneStepSettings(RLSCommon):
    """One-step predictor settings (defaults: Tuna et al. 2013, §VIII-B).

    Attributes
    ----------
    order : int
        N, past samples in the regressor [-]; 16 in Tuna's experiments.
    """

    order: int = 16

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.order) != self.order or self.order < 1:
            raise ValueError(f"order must be a positive integer, got {self.order!r}")


def make_rls(s: RLSCommon, batch: int, n: int, q: int, unit: float, counts):
    """The RLS kernel of settings ``s``, its SI prior weight δ in data units (``unit`` m each)."""
    return RecursiveLeastSquares(
        batch, n, q, s.forgetting_factor, s.delta / unit**2, s.p_max_factor, counts
    )


class OneStepRLS(DelayLinePredictor):
    """Vector RLS one-step predictor, iterated over the horizon (Tuna §V, eqs. 1–8)."""

    Settings = OneStepSettings

    def _allocate(self, d: int) -> None:
        s = self.settings
        N = s.order
        batch, n, q = (1, N * d, d) if s.correlated else (d, N, 1)
        self.rls = make_rls(s, batch, n, q, self.unit, self.counts)
        if s.init == "hold":  # A_1 = I
            if s.correlated:
                self.rls.W[0, :, :d] = np.eye(d)
            else:
                self.rls.W[:, 0, 0] = 1.0
        self.line = TappedDelayLine(N + 1, d)

    # regressor [z_{n−1}; …; z_{n−N}] and target z_n in the RLS layout
    def _xy(self, line: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        N = self.settings.order
        past = line[1 : N + 1]
        if self.settings.correlated:
            return past.reshape(1, -1), line[0][None, :]
        return past.T, line[0][:, None]

    def _update(self, z: np.ndarray) -> None:
        self._push(z)
        if self.line.real_run > self.settings.order:
            self.rls.update(*self._xy(self.line.buf))
        self.ready = self.line.filled >= self.settings.order

    def _next(self, past: np.ndarray) -> np.ndarray:
        """ẑ from the newest-first block ``past`` (N, d)."""
        W = self.rls.W
        if self.settings.correlated:
            return W[0] @ past.reshape(-1)
        return np.einsum("bi,ib->b", W[:, 0, :], past)

    def _predict(self, steps: int) -> np.ndarray:
        # newest-first scratch [ẑ_{n+K}, …, ẑ_{n+1}, z_n, …, z_{n−N+1}]: each forecast is
        # written just before the window that produced it, so nothing is shifted
        N, d = self.settings.order, self.d
        Nd = N * d
        buf = np.empty((steps + N) * d)
        buf[steps * d :] = self.line.buf[:N].reshape(-1)
        if self.settings.correlated:
            W = self.rls.W[0]
            for s in range(steps * d, 0, -d):
                np.dot(W, buf[s : s + Nd], out=buf[s - d : s])
        else:
            for s in range(steps * d, 0, -d):
                buf[s - d : s] = self._next(buf[s : s + Nd].reshape(N, d))
        return buf[: steps * d].reshape(steps, d)[::-1].copy()

    @property
    def weights(self) -> np.ndarray:
        """[A_1 … A_N] as (d, N·d) (correlated) or per-axis taps (d, N) (independent)."""
        if self.settings.correlated:
            return self.rls.W[0].copy()
        return self.rls.W[:, 0, :].copy()
