"""The open-loop study's rules, its settings and the plan of a track: its grid, the origins
scored, the fits, and each predictor's step timed for the estimate (the rules in full:
:mod:`rhmpc.openloop.recordings`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from rhmpc.experiment.fit_plan import FitPlan, plan_fits, step_seconds
from rhmpc.openloop.tracks import Track
from rhmpc.predictors import LEARNED, family, make_predictor, needs_torch, predictor_names
from rhmpc.predictors.registry import default_predictors, torch_available
from rhmpc.sim.recordings.points import on_grid

#: Leads 1 … DEFAULT_LEADS are scored [samples].
DEFAULT_LEADS = 5
#: Warm-up: the longer of this many seconds [s] …
WARMUP_SECONDS = 10.0
#: … and this fraction of the recording [-].
WARMUP_FRACTION = 0.25
#: Counter names of the predictors summed into ``rejected`` and ``repaired``.
REJECTED = ("innovation_rejected", "outliers_rejected")
REPAIRED = ("forecast_clamped", "forecast_nonfinite", "retracted")


@dataclass(frozen=True)
class OpenLoopSettings:
    """How the open-loop scoring runs.

    Attributes
    ----------
    predictors : tuple[str, ...]
        Predictor names (``rhmpc.predictors.predictor_names()``, not ``exact``); empty = the
        defaults (:func:`default_predictors`).
    leads : int
        L: leads 1 … L are scored, and the closed loop's lead K_loop [samples].
    warmup : float | None
        Seconds excluded from the start of each recording [s]; ``None`` = the longer of
        WARMUP_SECONDS and WARMUP_FRACTION of the recording. Not with ``split``.
    latency : float
        λ, the delivery latency of the samples to the controller [s] (0: each sample is
        available at its timestamp).
    horizon : float
        N·Ts, the MPC's reach beyond the newest tick [s] (50 × 0.5 ms).
    split : tuple[int, int] | None
        (TRAIN, END) [samples, from 0, on the recording's grid]: the fitted predictors are
        fitted on the samples before TRAIN (or on the training recordings), the forecasts
        issued in [TRAIN, END) are scored. ``None``: the warm-up rule.
    seed : int
        Seed of the fitted predictors' random draws (their ``seed`` setting).
    """

    predictors: tuple[str, ...] = ()
    leads: int = DEFAULT_LEADS
    warmup: float | None = None
    latency: float = 0.0
    horizon: float = 0.025
    split: tuple[int, int] | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        bad = [n for n in self.predictors if n not in predictor_names() or n == "exact"]
        if bad:
            valid = ", ".join(default_predictors(fitted=True))
            raise ValueError(f"unknown predictor(s) {', '.join(bad)}; valid: {valid}")
        if isinstance(self.leads, bool) or not isinstance(self.leads, int) or self.leads < 1:
            raise ValueError(f"leads must be an integer >= 1, got {self.leads!r}")
        if self.warmup is not None and not (math.isfinite(self.warmup) and self.warmup >= 0):
            raise ValueError(f"the warm-up must be >= 0 [s], got {self.warmup!r}")
        if not (math.isfinite(self.latency) and self.latency >= 0):
            raise ValueError(f"the latency must be >= 0 [s], got {self.latency!r}")
        if not (math.isfinite(self.horizon) and self.horizon > 0):
            raise ValueError(f"the horizon must be > 0 [s], got {self.horizon!r}")
        if self.split is not None:
            train, end = self.split
            if not 0 < train < end:
                raise ValueError(f"the split TRAIN:END must have 0 < TRAIN < END [samples], "
                                 f"got {train}:{end}")
            if self.warmup is not None:
                raise ValueError("a split scores from TRAIN: it takes no warm-up")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"the seed must be an integer >= 0, got {self.seed!r}")

    def names(self, fitted: bool = False) -> tuple[str, ...]:
        """The predictors to score; ``fitted``: whether there is something to fit on."""
        if not self.predictors:
            return default_predictors(fitted)
        fit_needed = [n for n in self.predictors if n in LEARNED]
        if fit_needed and not fitted:
            raise ValueError(f"{', '.join(fit_needed)} must be fitted before the run: give a "
                             "split TRAIN:END or training recordings")
        return self.predictors


def loop_lead(period: float, latency: float, horizon: float) -> int:
    """K_loop = ⌈(Δ + λ + N·Ts)/Δ⌉ [samples] (module docstring), robust to rounding."""
    return max(1, math.ceil((period + latency + horizon) / period - 1e-9))


def warmup_seconds(duration: float, warmup: float | None) -> float:
    """The warm-up [s]: ``warmup``, or max(WARMUP_SECONDS, WARMUP_FRACTION · duration)."""
    if warmup is not None:
        return float(warmup)
    return max(WARMUP_SECONDS, WARMUP_FRACTION * duration)


def left_out(names: Sequence[str]) -> list[str]:
    """The fitted predictors that could run here (PyTorch installed for a network) but are not
    among ``names``: those the default set leaves out."""
    return [n for n in LEARNED if n not in names and (not needs_torch(n) or torch_available())]


@dataclass
class TrackPlan:
    """What the study does on one track, planned before any of it runs.

    Attributes
    ----------
    track : Track
        The track.
    settings : OpenLoopSettings
        The study's settings.
    grid : ndarray, shape (T, P, d)
        Its samples on its own grid [m] (NaN where missing), the POI first.
    t : ndarray, shape (T,)
        The grid's times [s].
    first, end : int
        The origins scored: [first, end) of the grid.
    warmup : float
        The span before ``first`` [s].
    leads : list of int
        The leads scored [samples], the closed loop's ``k_loop`` among them.
    k_loop : int
        K_loop, the lead the closed loop needs [samples].
    names : tuple of str
        The predictors scored.
    train : list of ndarray or None
        What the fitted predictors are fitted on (None: nothing to fit).
    where : str
        Those samples in words.
    fits : list of FitPlan
        The fits (:func:`rhmpc.experiment.fit_plan.plan_fits`).
    omitted : list of FitPlan
        The fitted predictors the default set leaves out, planned to say what they would
        cost.
    steps : dict
        name → the time of one sample's update and forecast [s], where timed.
    """

    track: Track
    settings: OpenLoopSettings
    grid: np.ndarray
    t: np.ndarray
    first: int
    end: int
    warmup: float
    leads: list[int]
    k_loop: int
    names: tuple[str, ...]
    train: list[np.ndarray] | None
    where: str
    fits: list[FitPlan] = field(default_factory=list)
    omitted: list[FitPlan] = field(default_factory=list)
    steps: dict[str, float] = field(default_factory=dict)

    @property
    def fitting_s(self) -> float:
        """The fits' estimated time [s] (those not probed, about a second each, left out)."""
        return sum(p.estimate_s or 0.0 for p in self.fits)

    def scoring_s(self, name: str | None = None) -> float:
        """The scoring's estimated time [s]: each predictor's step over the ``end`` samples it
        is fed (of ``name`` alone if given)."""
        steps = self.steps if name is None else {name: self.steps.get(name, 0.0)}
        return self.end * sum(steps.values())


def plan_track(track: Track, settings: OpenLoopSettings,
               train: list[np.ndarray] | None = None,
               progress: Callable[[str], None] | None = None,
               where: str = "the training recordings") -> TrackPlan:
    """The plan of ``track``: its grid, the origins scored, the fits, and each predictor's step
    timed on :data:`~rhmpc.experiment.fit_plan.STEP_SAMPLES` of its samples (a fitted network's
    from its probe; the combination's, the sum of its members').

    ``train``: the recordings to fit the fitted predictors on
    (:func:`rhmpc.sim.recordings.training_series`); default, with a split, the track's samples
    before TRAIN; ``where``: those samples in words. ``progress(text)`` hears that the fits
    are timed, before they are.

    Raises
    ------
    ValueError
        The warm-up leaves nothing to score (the message names the lengths), a split beyond
        the recording, or fitted predictors and nothing to fit them on.
    """
    period = track.period
    wide = track.points().reshape(track.t.size, -1)
    t, wide = on_grid(track.t, wide, period)
    grid = wide.reshape(wide.shape[0], -1, track.z.shape[1])
    k_loop = loop_lead(period, settings.latency, settings.horizon)
    leads = sorted({*range(1, settings.leads + 1), k_loop})
    first, end, warmup = _origins(track, t, settings, leads[-1])
    if train is None and settings.split is not None:
        train = [grid[:first]]
        where = (f"frames 0–{first - 1} of {track.label} (the frames before TRAIN = {first}; "
                 f"the forecasts issued at frames {first}–{end - 1} are scored)")
    names = settings.names(fitted=train is not None)
    plan = TrackPlan(track, settings, grid, t, first, end, warmup, leads, k_loop, names, train,
                     where)
    if train and any(n in LEARNED for n in names):
        if progress is not None:
            progress(f"timing the fits on {track.label} (each network predictor on a few "
                     "epochs of one network) and each predictor's step, for the estimate")
        plan.fits = plan_fits(names, period, train, leads[-1], settings.seed)
        spare = [] if settings.predictors or not plan.fits else left_out(names)
        plan.omitted = plan_fits(spare, period, train, leads[-1], settings.seed)
    fitted = {f.name: f.step_s for f in plan.fits}
    for name in names:
        if name in fitted:
            if fitted[name] is not None:
                plan.steps[name] = fitted[name]
        elif name != "combination":
            plan.steps[name] = step_seconds(make_predictor(name, dt=period), grid, leads[-1])
    if "combination" in names:
        plan.steps["combination"] = sum(plan.steps.get(n, 0.0) for n in scored_members(
            names))
    return plan


def scored_members(names: Sequence[str]) -> list[str]:
    """The members of the study's combination: the other scored predictors that are not
    baselines."""
    return [n for n in names if family(n) not in ("baseline", "combination")]


def _origins(track: Track, t: np.ndarray, settings: OpenLoopSettings, last_lead: int
             ) -> tuple[int, int, float]:
    """(first, end, warm-up [s]): the origins scored, [first, end) on the grid ``t``."""
    duration = float(track.t[-1] - track.t[0])
    if settings.split is not None:
        first, end = settings.split
        if first + 1 >= t.size:
            raise ValueError(f"{track.label}: holds {t.size} samples; the split starts "
                             f"scoring at sample {first}")
        return first, min(end, t.size), float(t[first] - t[0])
    warmup = warmup_seconds(duration, settings.warmup)
    first = int(np.searchsorted(t, t[0] + warmup - 1e-9))
    if first + last_lead >= t.size:
        raise ValueError(f"{track.label}: lasts {duration:.2f} s; a warm-up of {warmup:.2f} s "
                         f"and a lead of {last_lead} samples leave nothing to score "
                         "(shorten it with --warmup)")
    return first, t.size, warmup
