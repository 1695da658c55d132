"""Online combination: the members' forecasts weighted, per lead, by their recent errors.

Every member runs on the same samples (``others`` passed on); after update n each member m
forecasts leads 1 … L, and the combination forecasts

    ẑ_{n+k} = Σ_m w_{m,k} ẑ^m_{n+k},   w_{m,k} = e_{m,k}^{−κ} / Σ_j e_{j,k}^{−κ},

with e_{m,k} the member's discounted mean squared miss at lead k, each sample weighing
γ = 1 − Δ/``memory`` of the next one: the discounted-MSE combination of Stock & Watson (2004,
"Combination forecasts of output growth in a seven-country data set", J. Forecast. 23:405;
Timmermann 2006, *Handbook of Economic Forecasting* 1:135, §7), which generalises Bates &
Granger's (1969) inverse-MSE weights (κ = 1); κ = 0 is the plain average, κ → ∞ the
selection of the best member. The weights are free of the data's unit.

The exponent κ.  For independent unbiased errors the best weights are ∝ 1/MSE (κ = 1); the
members here share most of their error (the motion none of them foresees), which calls for
more weight on the best, and their recent MSEs are estimated from few samples, which calls
for less: κ = 2 lies between. The combination's mean squared miss is at most Σ_m w_m e_m
(Jensen: the squared miss is convex), so a member's weight costs in proportion to its excess
error, and members of near-equal error share the weight and partly cancel each other's
misses.

Before the first scored miss the members count equally, or by their prior errors: a member
fitted before the run brings the RMS miss of its validation (``validation_rms``), an online
member its own running one, each worth ``prior_seconds`` of samples; a member without one
is taken to be as bad as the worst that has one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from predictors.base import Predictor, PredictorSettings

__all__ = ["Combination", "CombinationSettings"]


@dataclass(frozen=True)
class CombinationSettings(PredictorSettings):
    """Combination settings.

    Attributes
    ----------
    members : tuple of str
        Predictor names (``predictors.make_predictor``); the default: the adaptive linear
        predictors, POI-only and multi-point, which need no fitting.
    leads : int
        L, leads scored and weighted on their own [samples]; longer ones take lead L's
        weights. 4 (160 ms at 25 frames/s).
    memory : float
        Memory of the discounted errors [s]; 10 s, the members' own running error's
        (``Predictor.ERROR_MEMORY_SECONDS``): a dozen beats.
    exponent : float
        κ ≥ 0 [-] of the weights e^{−κ} (module docstring); 2.
    prior_seconds : float
        Weight of the members' prior errors, in seconds of samples [s]; 2 s, a couple of
        beats, after which the combination's own scoring dominates.
    score_from : int
        The samples before this one (counted from 0) are not scored: where members fitted
        before the run were fitted on them, their misses there are no forecast errors. The
        priors are taken at it.
    """

    members: tuple[str, ...] = ("one-step", "generalized", "st-rls")
    leads: int = 4
    memory: float = 10.0
    exponent: float = 2.0
    prior_seconds: float = 2.0
    score_from: int = 0

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.members or "combination" in self.members:
            raise ValueError(f"members must name one predictor or more (not a combination), "
                             f"got {self.members!r}")
        if isinstance(self.leads, bool) or int(self.leads) != self.leads or self.leads < 1:
            raise ValueError(f"leads must be a positive integer, got {self.leads!r}")
        if not (self.memory > 0.0 and math.isfinite(self.memory)):
            raise ValueError(f"memory must be > 0 [s], got {self.memory!r}")
        if not (self.exponent >= 0.0 and math.isfinite(self.exponent)):
            raise ValueError(f"exponent must be >= 0, got {self.exponent!r}")
        if not self.prior_seconds >= 0.0:
            raise ValueError(f"prior_seconds must be >= 0, got {self.prior_seconds!r}")
        if int(self.score_from) != self.score_from or self.score_from < 0:
            raise ValueError(f"score_from must be an integer >= 0, got {self.score_from!r}")


class Combination(Predictor):
    """Discounted-MSE weighted average of its members' forecasts, per lead (module docstring).

    Parameters
    ----------
    dt : float
        Sample period [s].
    settings : CombinationSettings, optional
    members : sequence of Predictor
        The members themselves (e.g. already fitted), one per name of ``settings.members``
        (``make_predictor("combination", …)`` builds them by name).
    """

    Settings = CombinationSettings
    multi_point = True

    def __init__(self, dt: float, settings: CombinationSettings | None = None,
                 members: Sequence[Predictor] | None = None) -> None:
        s = self.Settings() if settings is None else settings
        if members is None:
            raise ValueError("a combination is built with its members: "
                             "make_predictor('combination', dt, members=(...)) builds them by "
                             "name, Combination(dt, settings, members) takes them as they are")
        if len(members) != len(s.members):
            raise ValueError(f"{len(members)} members given for the {len(s.members)} names "
                             f"{', '.join(s.members)}")
        self.members = list(members)
        super().__init__(dt, s)

    def fit(self, series, progress=None) -> Combination:
        """Fit the members that are fitted before the run (``fit``) to ``series``."""
        for name, m in zip(self.settings.members, self.members, strict=True):
            if hasattr(m, "fit"):
                m.fit(series, None if progress is None else
                      (lambda text, name=name: progress(f"{name}: {text}")))
        self.reset()
        return self

    def reset(self) -> None:
        super().reset()
        for m in getattr(self, "members", ()):
            m.reset()

    @property
    def weights(self) -> np.ndarray:
        """(K, L) the members' weights per lead (columns sum to 1)."""
        if self.d is None:
            return np.full((len(self.members), self.settings.leads), 1.0 / len(self.members))
        return self._weights()

    # -- the contract's hooks -----------------------------------------------------
    def _allocate(self, d: int) -> None:
        K, L = len(self.members), self.settings.leads
        self._fc = np.full((L, K, L, d), np.nan)  # ring by issue: forecasts of update n
        self._issued = np.full(L, -1, dtype=np.int64)
        self._sq = np.zeros((K, L))  # discounted Σ squared misses
        self._count = np.zeros(L)  # discounted Σ 1
        self._gamma = max(0.0, 1.0 - self.dt / self.settings.memory)
        self._primed = False

    def _pass(self, z: np.ndarray | None) -> None:
        others = self.others
        for m in self.members:
            m.update(z, others)

    def _update(self, z: np.ndarray) -> None:
        self._pass(z)
        if self.n > self.settings.score_from:  # sample n − 1, counted from 0
            self._prime()
            self._score(z)
        self._record()

    def _missing(self) -> None:
        self._pass(None)
        self._record()

    def _record(self) -> None:
        """Every member's forecast of leads 1 … L from this update."""
        slot = self.n % self.settings.leads
        self._issued[slot] = self.n
        for i, m in enumerate(self.members):
            try:
                self._fc[slot, i] = m.predict(self.settings.leads)
            except RuntimeError:  # a member without a valid sample yet
                self._fc[slot, i] = np.nan
        self.ready = bool(np.isfinite(self._fc[slot]).all())

    def _score(self, z: np.ndarray) -> None:
        """The misses of the forecasts that reach sample n, into the discounted sums."""
        L, g = self.settings.leads, self._gamma
        for k in range(1, L + 1):
            slot = (self.n - k) % L
            if self._issued[slot] != self.n - k:
                continue
            miss = self._fc[slot, :, k - 1] - z
            e2 = np.einsum("ij,ij->i", miss, miss)
            if not np.isfinite(e2).all():
                continue
            self._sq[:, k - 1] = g * self._sq[:, k - 1] + e2
            self._count[k - 1] = g * self._count[k - 1] + 1.0

    def _prime(self) -> None:
        """At the first scored update: the members' prior errors, worth ``prior_seconds``."""
        if self._primed:
            return
        self._primed = True
        L = self.settings.leads
        prior = np.full((len(self.members), L), np.nan)
        for i, m in enumerate(self.members):
            prior[i] = _prior_rms(m, L)
        if not np.isfinite(prior).any() or self.settings.prior_seconds <= 0.0:
            return
        worst = np.nanmax(prior, axis=0)
        prior = np.where(np.isfinite(prior), prior, worst)
        w = self.settings.prior_seconds / self.dt
        self._sq += w * prior**2
        self._count += w

    def _weights(self) -> np.ndarray:
        """(K, L) w_{m,k} ∝ e_{m,k}^{−κ}; equal where nothing is scored yet (and among the
        members that have not missed at all, if some have not)."""
        K, L = self._sq.shape
        w = np.full((K, L), 1.0 / K)
        for k in np.flatnonzero(self._count > 0.0):
            e = self._sq[:, k] / self._count[k]
            best = e.min()
            u = (e / best) ** -self.settings.exponent if best > 0.0 else (e == 0.0) * 1.0
            w[:, k] = u / u.sum()
        return w

    def _predict(self, steps: int) -> np.ndarray:
        L = self.settings.leads
        slot = self.n % L
        if steps <= L and self._issued[slot] == self.n:
            f = self._fc[slot, :, :steps]
        else:
            f = np.stack([m.predict(steps) for m in self.members])
        w = self._weights()
        w = w[:, np.minimum(np.arange(steps), L - 1)]
        return np.einsum("ik,ikj->kj", w, f)


def _prior_rms(member: Predictor, leads: int) -> np.ndarray:
    """(L,) a member's prior RMS miss [its data units]: a fitted member's validation RMS, an
    online one's running RMS; NaN where it has none."""
    out = np.full(leads, np.nan)
    if hasattr(member, "fit"):
        model = getattr(member, "model", None) or {}
        if model.get("validation_rms") is None or not member.unit:
            return out
        v = np.asarray(model["validation_rms"], dtype=float) / member.unit
    elif member.d is not None:
        v = member.forecast_error_rms
    else:
        return out
    if v.size == 0:
        return out
    n = min(leads, v.size)
    out[:n] = v[:n]
    out[n:] = v[n - 1] if n else np.nan
    return out
