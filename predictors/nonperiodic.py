"""The part of the motion a Fourier-series model does not explain: its size and its course.

In vivo most of a tracked point's motion is not periodic: beats differ in shape, amplitude
and timing. A Fourier-series EKF that trusts each sample to its sensor's σ_R explains that
variation as changes of phase, rate and amplitude, and forecasts from a state that chases
the newest sample. :class:`NonPeriodic` gives such a filter two things, both from the
residual of its *current* state over the recent samples,

    e_{n−j} = z_{n−j} − ŷ_{n−j|n},   j = 0 … L − 1,

(ŷ_{t|n} its model with the newest state, evaluated at past sample t):

1. **R that follows the data** (covariance matching, Mehra 1972, IEEE Trans. Autom. Control
   17:693, §IV: R̂ = the residual covariance minus the model's share H P Hᵀ; Richa et al. 2010
   §II-C propose "an adaptive update of the filter's uncertainty parameters"). Over the last
   beat (L = 2π/(ω̂Δt) samples) the residual has variance γ₀ and lag-one correlation ρ. A
   residual correlated from sample to sample carries less information about a slowly varying
   state than white noise of the same variance: what counts is its long-run variance,
   γ₀(1 + ρ)/(1 − ρ) for an AR(1) (the variance of a mean of n such samples is that over n;
   Bayley & Hammersley 1946, J. R. Stat. Soc. Suppl. 8:184). Per axis

       R̂ ← R̂ + (R* − R̂)/L,   R* = max(σ_R², γ₀(1 + ρ)/(1 − ρ) − (H P⁻ Hᵀ)_aa),

   per sample (applied every L/16 samples with weight 1/16: the same memory of one beat),

   ρ clipped to [0, ``RHO_MAX``]. The residual of the current state over a whole beat is large
   when the state chases the newest samples (in-vivo motion: R̂ ≈ 1–2 mm), and small when
   the model holds the motion (the replicas: R̂ = σ_R); the one-step innovations cannot tell
   the two apart, since a chasing filter whitens them. R̂ belongs to the data, not to a fit:
   it is kept through re-fits.
2. **A forecast of the residual** (:class:`rhmpc.predictors.residual.ResidualAR`), learnt on the
   same residuals, so that ẑ_{n+k} = ŷ_{n+k|n} + ê_{n+k|n} starts from the newest sample.

Samples are kept newest first (:class:`rhmpc.predictors.residual.RecentSamples`); a missing or
gated sample is NaN: no residual, nothing learnt from a window holding it.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections import Counter
from collections.abc import Callable

import numpy as np
from scipy.special import gammaincinv

from rhmpc.predictors.base import Predictor
from rhmpc.predictors.residual import RecentSamples, ResidualAR

__all__ = ["FourierPredictor", "NonPeriodic", "long_run_variance"]

#: Prior weight δ of the residual model's RLS [m²], as the RLS predictors' (P₀ = I/δ).
RESIDUAL_DELTA = 1e-8


def long_run_variance(e: np.ndarray, rho_max: float = 0.95) -> np.ndarray:
    """γ₀(1 + ρ)/(1 − ρ) per column of ``e`` (T, d) (finite rows), ρ = γ₁/γ₀ ∈ [0, ρ_max]."""
    e = e[np.isfinite(e).all(axis=1)]
    g0 = np.mean(e * e, axis=0)
    g1 = np.mean(e[1:] * e[:-1], axis=0)
    rho = np.clip(g1 / np.maximum(g0, 1e-300), 0.0, rho_max)
    return g0 * (1.0 + rho) / (1.0 - rho)


class NonPeriodic:
    """Beat-residual R̂ and residual AR of a Fourier-series filter (module docstring).

    Parameters
    ----------
    d : int
        Axes.
    dt : float
        Sample period [s].
    floor : float
        σ_R², the sensor's variance, in data units² (R̂'s floor and start).
    adaptive_r : bool
        Follow R̂ (else R = ``floor``).
    residual_order : int
        p of the residual AR; 0: none.
    forgetting : float
        λ of its RLS [-].
    unit : float
        Metres per data unit.
    slowest_hz : float
        Lowest heart rate the filter can hold [Hz]: one beat of samples is kept.
    counts : Counter
        The owner's event counts.
    """

    #: ρ ≤ 0.95: long-run factor ≤ 39; a residual still correlated beyond that over a beat
    #: is the model's own transient (it decays as the filter converges), not motion.
    RHO_MAX = 0.95
    #: R̂ is updated this many times per beat [-]
    R_UPDATES = 16

    def __init__(self, d: int, dt: float, floor: float, adaptive_r: bool, residual_order: int,
                 forgetting: float, unit: float, slowest_hz: float, counts: Counter) -> None:
        self.dt, self.floor, self.adaptive = dt, float(floor), bool(adaptive_r)
        self.r = np.full(d, self.floor)
        self.residual = None
        if residual_order:
            self.residual = ResidualAR(d, residual_order, forgetting,
                                       RESIDUAL_DELTA / unit**2, counts)
        beat = math.ceil(1.0 / (slowest_hz * dt)) if adaptive_r else 0
        self.recent = RecentSamples(max(beat, residual_order + 1, 1), d)
        self.e = np.zeros((residual_order + 1, d))
        self._tick = 0

    def push(self, z: np.ndarray | float) -> None:
        """A new sample (NaN: missing)."""
        self.recent.push(z)

    def reject(self) -> None:
        """The newest sample was gated out: it is no residual either."""
        self.recent.z[0] = np.nan

    def follow(self, model: Callable[[np.ndarray], np.ndarray], omega: float,
               hph: np.ndarray | None, learn: bool) -> None:
        """Residuals of the current state (``model(k)``: ŷ at offsets k ≤ 0, (len(k), d)); then
        R̂ from the last beat (with diag H P⁻ Hᵀ ``hph``) and one RLS step if ``learn``."""
        p = 0 if self.residual is None else self.residual.p
        beat = max(8, min(round(2 * math.pi / (omega * self.dt)), len(self.recent.z)))
        every = max(1, beat // self.R_UPDATES)  # R̂ moves by 1/beat per sample, so every
        self._tick += 1  # ``every`` samples by every/beat: the same memory at less cost
        due = self.adaptive and hph is not None and learn and self._tick % every == 0
        lags = max(beat if due else 0, p + 1)
        y = model(-np.arange(float(lags)))
        e = self.recent.z[:lags] - y
        self.e = e[: p + 1]
        if due:
            self._follow_r(e[:beat], hph, beat / every)
        if self.residual is not None and learn:
            self.residual.learn(self.e, y[0] - y[1])

    def _follow_r(self, e: np.ndarray, hph: np.ndarray, memory: float) -> None:
        """R̂ ← R̂ + (R* − R̂)/memory (module docstring)."""
        if np.isfinite(e).all(axis=1).sum() < 8:
            return
        target = np.maximum(long_run_variance(e, self.RHO_MAX) - hph, self.floor)
        self.r += (target - self.r) / max(memory, 1.0)

    def restart(self) -> None:
        """After a (re)fit: the residual AR's prior at its weights, worth p residuals of R̂."""
        if self.residual is not None:
            self.residual.restart(self.r, self.residual.p)

    def forecast(self, increments: np.ndarray) -> np.ndarray:
        """ê_{n+1…n+K} (K, d) given the model's increments ŷ_{n+k|n} − ŷ_{n+k−1|n} (K, d)."""
        if self.residual is None:
            return np.zeros_like(increments)
        return self.residual.forecast(self.e, increments, len(increments))


class FourierPredictor(Predictor):
    """Base of the Fourier-series predictors (``ekf``, ``dual-ekf``, ``wflc``).

    A subclass has a model ``_model(k)`` of the motion k samples from the newest (past ones
    negative), its rate ω̂ (``_rate``), and, when ``_rest`` is set, the model's non-periodic
    part (:class:`NonPeriodic`), which this class keeps up and adds to the forecast:

        ẑ_{n+k|n} = ŷ_{n+k|n} + ê_{n+k|n},

    ê the residual AR's forecast driven by the model's increments ŷ_{n+k|n} − ŷ_{n+k−1|n}.
    """

    #: the non-periodic part, if the settings ask for one
    _rest: NonPeriodic | None = None
    #: diag H P⁻ Hᵀ of the last correction (the EKFs; R̂ subtracts it), data units²
    _hph: np.ndarray | None = None

    @abstractmethod
    def _model(self, k: np.ndarray) -> np.ndarray:
        """ŷ at offsets ``k`` from the newest sample, (len(k), d)."""

    @abstractmethod
    def _rate(self) -> float:
        """ω̂ [rad/s], the heart rate the model runs at."""

    def _follow(self, learn: bool) -> None:
        """The non-periodic part from the current state; learn from it if ``learn``."""
        if self._rest is not None and self.ready:
            self._rest.follow(self._model, self._rate(), self._hph, learn)

    def _rest_missing(self) -> None:
        """A missing sample reaches the non-periodic part (after the model has advanced)."""
        if self._rest is not None:
            self._rest.push(np.nan)
            self._follow(learn=False)

    def _predict(self, steps: int) -> np.ndarray:
        if self._rest is None:
            return self._model(np.arange(1.0, steps + 1.0))
        y = self._model(np.arange(0.0, steps + 1.0))  # ŷ_{n+k|n} + ê_{n+k|n}
        return y[1:] + self._rest.forecast(np.diff(y, axis=0))


def chi2_quantile(p: float, d: int) -> float:
    """The χ²_d quantile of probability ``p``: 2 P⁻¹(d/2, p), P the regularised lower incomplete
    gamma function (``scipy.stats.chi2.ppf``'s formula, without importing ``scipy.stats``)."""
    return float(2.0 * gammaincinv(d / 2.0, p))
