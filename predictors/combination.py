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
is taken to be as bad as the worst that has one. A member fitted before the run that has not
been fitted (there was nothing to fit it on) takes no part: the others run and share the
weights.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from rhmpc.predictors.base import Predictor, PredictorSettings
from rhmpc.predictors.learned.fitted import FitWarning

__all__ = ["Combination", "CombinationSettings", "MemberTime"]


@dataclass(frozen=True)
class CombinationSettings(PredictorSettings):
    """Combination settings.

    Attributes
    ----------
    members : tuple of str
        Predictor names (``rhmpc.predictors.make_predictor``); empty (the default): every default
        predictor that is not a baseline, the fitted ones included
        (``rhmpc.predictors.registry.combination_members``), as in the open-loop study.
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
    models : tuple of str
        Saved models (``rhmpc predict --save-models``) of members fitted before the run, each
        loaded into the member of its kind (``rhmpc.predictors.registry.load_model``); those without
        one are fitted by :meth:`Combination.fit`.
    """

    members: tuple[str, ...] = ()
    leads: int = 4
    memory: float = 10.0
    exponent: float = 2.0
    prior_seconds: float = 2.0
    score_from: int = 0
    models: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        super().__post_init__()
        if "combination" in self.members:
            raise ValueError(f"members must name predictors other than a combination, "
                             f"got {self.members!r}")
        if isinstance(self.leads, bool) or int(self.leads) != self.leads or self.leads < 1:
            raise ValueError(f"leads must be a positive integer, got {self.leads!r}")
        if not (self.memory > 0.0 and math.isfinite(self.memory)):
            raise ValueError(f"memory must be > 0 [s], got {self.memory!r}")
        if not (self.exponent >= 0.0 and math.isfinite(self.exponent)):
            raise ValueError(f"exponent must be >= 0, got {self.exponent!r}")
        if not self.prior_seconds >= 0.0:
            raise ValueError(f"prior_seconds must be >= 0, got {self.prior_seconds!r}")
        if isinstance(self.models, list):  # as TOML reads it
            object.__setattr__(self, "models", tuple(self.models))
        if not all(isinstance(f, str) for f in self.models):
            raise ValueError(f"models must be file names, got {self.models!r}")
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
        #: each member's update-and-forecast time against the sample period
        self.member_time = MemberTime(s.members, dt)
        super().__init__(dt, s)

    @property
    def fitted(self) -> bool:
        """Whether every member fitted before the run has been (True without such members)."""
        return all(getattr(m, "fitted", True) for m in self.members if hasattr(m, "fit"))

    def score_after(self, samples: int) -> None:
        """Score no miss of the first ``samples`` updates (``score_from``): the samples its
        fitted members learnt from, replayed, where their misses are no forecast errors."""
        self.settings = replace(self.settings, score_from=int(samples))

    def fit(self, series, progress=None) -> Combination:
        """Fit the members that are fitted before the run (``fit``) and not yet fitted (nor
        loaded from a file) to ``series``. A member that cannot be fitted on them (too few
        samples for its model) takes no part, with a :class:`FitWarning` naming it."""
        for name, m in zip(self.settings.members, self.members, strict=True):
            if hasattr(m, "fit") and not m.fitted:
                try:
                    m.fit(series, None if progress is None else
                          (lambda text, name=name: progress(f"{name}: {text}")))
                except ValueError as exc:
                    warnings.warn(f"the combination runs without {name}: {exc}", FitWarning,
                                  stacklevel=2)
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
        #: the members that run: all but those fitted before the run and not fitted
        self._active = np.array([getattr(m, "fitted", True) for m in self.members])
        if not self._active.any():
            raise RuntimeError("no member of the combination can run: every one must be "
                               "fitted first (fit(series))")

    def _step(self, z: np.ndarray | None) -> np.ndarray:
        """Every member's update with ``z`` (None: missing) and its forecast of leads 1 … L,
        (K, L, d), each member's pair timed (:attr:`member_time`)."""
        others, L = self.others, self.settings.leads
        fc = np.full((len(self.members), L, self.d), np.nan)
        for i in np.flatnonzero(self._active):
            m = self.members[i]
            tic = time.perf_counter_ns()
            m.update(z, others)
            try:
                fc[i] = m.predict(L)
            except RuntimeError:  # a member without a valid sample yet
                pass
            self.member_time.add(i, time.perf_counter_ns() - tic)
        return fc

    def _update(self, z: np.ndarray) -> None:
        fc = self._step(z)
        if self.n > self.settings.score_from:  # sample n − 1, counted from 0
            self._prime()
            self._score(z)
        self._record(fc)

    def _missing(self) -> None:
        self._record(self._step(None))

    def _record(self, fc: np.ndarray) -> None:
        """Keep every member's forecast of leads 1 … L from this update (after the scoring,
        which reads the slot it replaces)."""
        slot = self.n % self.settings.leads
        self._issued[slot] = self.n
        self._fc[slot] = fc
        self.ready = bool(np.isfinite(fc[self._active]).all())

    def _score(self, z: np.ndarray) -> None:
        """The misses of the forecasts that reach sample n, into the discounted sums."""
        L, g = self.settings.leads, self._gamma
        for k in range(1, L + 1):
            slot = (self.n - k) % L
            if self._issued[slot] != self.n - k:
                continue
            miss = self._fc[slot, :, k - 1] - z
            e2 = np.einsum("ij,ij->i", miss, miss)
            if not np.isfinite(e2[self._active]).all():
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
        active = self._active
        K, L = self._sq.shape
        w = np.zeros((K, L))
        w[active] = 1.0 / active.sum()
        for k in np.flatnonzero(self._count > 0.0):
            e = self._sq[active, k] / self._count[k]
            best = e.min()
            u = (e / best) ** -self.settings.exponent if best > 0.0 else (e == 0.0) * 1.0
            w[active, k] = u / u.sum()
        return w

    def _predict(self, steps: int) -> np.ndarray:
        L = self.settings.leads
        slot = self.n % L
        active = self._active
        if steps <= L and self._issued[slot] == self.n:
            f = self._fc[slot, active, :steps]
        else:
            f = np.stack([m.predict(steps) for m, a in zip(self.members, active, strict=True)
                          if a])
        w = self._weights()[active][:, np.minimum(np.arange(steps), L - 1)]
        return np.einsum("ik,ikj->kj", w, f)


class MemberTime:
    """Each member's time for one update and its forecast, against the sample period Δ: the
    budget a member must fit in on one core, as the combination runs them one after another.

    Parameters
    ----------
    names : sequence of str
        The members' names.
    period : float
        Δ, the sample period [s].
    """

    def __init__(self, names: Sequence[str], period: float) -> None:
        self.names, self.period_ns = tuple(names), 1e9 * period
        K = len(self.names)
        self.total, self.max = np.zeros(K), np.zeros(K)
        self.over, self.n = np.zeros(K, dtype=np.int64), np.zeros(K, dtype=np.int64)

    def add(self, i: int, ns: int) -> None:
        """Member ``i`` took ``ns`` [ns] for one update and its forecast."""
        self.total[i] += ns
        self.max[i] = max(self.max[i], ns)
        self.over[i] += ns > self.period_ns
        self.n[i] += 1

    def summary(self) -> dict:
        """Per member: ``mean_us``, ``max_us`` and ``over_period`` (updates longer than Δ)."""
        return {name: {"mean_us": float(self.total[i] / self.n[i] / 1e3) if self.n[i] else None,
                       "max_us": float(self.max[i] / 1e3), "over_period": int(self.over[i])}
                for i, name in enumerate(self.names)}


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
