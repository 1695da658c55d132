"""AR model with the recursive covariance estimator, plain and fading (Yuen et al. 2008, §III-B/C).

Model (eq. 4): y[k] = Σ_{i=1}^{n} α_i y[k−i], one model per axis.  Estimator (eqs. 5–6):

    R[k] = f R[k−1] + Z[k]ᵀ Z[k],   α̂[k] = α̂[k−1] + R[k]⁻¹ Z[k]ᵀ (z[k] − Z[k] α̂[k−1]),

with Z[k] = [z[k−1], …, z[k−n]], fading factor f (f = 1: "AR filter", f < 1:
"fading AR filter") and α̂[0] = 0.  This is exactly exponentially weighted RLS with
P = R⁻¹ and λ = f, so it runs on the shared Sherman–Morrison kernel; Yuen's R[0] = 0
(singular) becomes R[0] = δ I with a tiny δ.  Forecasts iterate eq. (4).

Cost per update: d·(2n² + 2n) multiply-adds (n = 30: ≈ 1.9k per axis).
"""

from __future__ import annotations

from dataclasses import dataclass

from rhmpc.predictors.rls_one_step import OneStepRLS, OneStepSettings

__all__ = ["ARSettings", "AutoregressivePredictor"]


@dataclass(frozen=True)
class ARSettings(OneStepSettings):
    """AR / fading AR settings (Yuen et al. 2008).

    Attributes
    ----------
    order : int
        n, AR order [-]; 30 (AIC on the mitral trajectory).
    forgetting_factor : float
        Fading factor f ∈ (0, 1] [-]; 1 for the AR filter, 0.985 for the fading AR filter.
    delta : float
        R[0] = δ I [m²]; tiny, standing in for Yuen's R[0] = 0.
    init : str
        α̂[0]: ``"zeros"`` as in Yuen.
    correlated : bool
        False: one scalar model per axis, as in Yuen.
    """

    order: int = 30
    forgetting_factor: float = 1.0
    delta: float = 1e-12
    init: str = "zeros"
    correlated: bool = False


class AutoregressivePredictor(OneStepRLS):
    """AR (f = 1) or fading AR (f < 1) predictor of Yuen et al. 2008 (§III-B/C)."""

    Settings = ARSettings
