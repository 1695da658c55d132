"""Every predictor on a user's recordings, open loop, each at the recording's own rate.

Each predictor is built with ``make_predictor(name, dt=Δ)``, Δ = 1/rate the file's median
sample period, and sees every raw sample once, in order (a missing sample, NaN or a gap in
the timestamps, is fed as missing). After every update n past the warm-up it forecasts
ẑ_{n+1|n} … ẑ_{n+K|n}; the error at lead k is e_k(n) = ‖ẑ_{n+k|n} − z_{n+k}‖, scored where
z_{n+k} was measured. Reported per lead: RMS and max of e_k [mm], the ratio of the RMS to
the hold forecast's (ẑ_{n+k|n} = z_n) at the same lead, and the predictor's events over the
scored part.

Rules
-----
Warm-up
    The first max(10 s, 25 % of the recording) are excluded (``warmup`` overrides it): the
    predictors converge there, as the closed loop's settling time lets them.
Lead the closed loop needs
    K_loop = ⌈(Δ + λ + N·Ts) / Δ⌉ samples: the forecast made from a sample serves the loop
    until the next sample arrives, one period Δ later plus the delivery latency λ, and must
    reach the MPC's horizon N·Ts (25 ms) beyond that. At 25 Hz: ⌈(40 + 0 + 25)/40⌉ = 2.
Events
    ``rejected``: samples the predictor's own gate refused (``innovation_rejected``, the
    Fourier EKFs); ``repaired``: forecasts its divergence guard repaired (``forecast_clamped``,
    ``forecast_nonfinite``) and samples it retracted (``retracted``); ``missing``: samples
    fed as missing. The closed loop's outlier gate is not part of the open loop.
Several points
    A file of several tracked points (:mod:`rhmpc.sim.recordings.points`) is scored point by point;
    with ``mean`` the study adds a row per predictor and lead whose errors are the means over
    the points. With a point of interest (``poi``), that point is scored and every predictor
    that reads the other points (``multi_point``) is fed them, sample by sample: at update n
    the samples ≤ n of every point.
The literature's protocol (``split`` = (TRAIN, END))
    The predictors fitted before the run (``rhmpc.predictors.LEARNED``) are fitted on the samples
    before TRAIN (all points, the POI first), or on other recordings (``train``); every other
    predictor runs causally from the first sample; the forecasts issued in [TRAIN, END) are
    scored, at leads 1 … L. Without ``split`` the warm-up rule holds, and the fitted
    predictors take part only when there are training recordings.
Families
    Each row names its predictor's family (``rhmpc.predictors.family``): ``baseline``,
    ``adaptive``, ``multi-point``, ``learned`` or ``combination``. The combination weighs the
    other scored predictors that are not baselines, per lead, by their recent errors; in the
    literature's protocol it scores nothing before TRAIN, where the fitted members' misses are
    not forecast errors, and starts from their validation errors.

Estimates
    Every track is planned before any work: the fits from a probe of a few epochs of one
    network (:mod:`rhmpc.experiment.fit_plan`) or the cache, each predictor's step (its update
    and forecast of one sample) timed on a few of the track's samples, a fitted network's on
    its probe. The whole — the fits and the scoring — is said before the first fit, and each
    predictor's scoring as it starts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from rhmpc.experiment.fit_plan import describe, duration, fit_all
from rhmpc.openloop.plan import (
    WARMUP_FRACTION,
    WARMUP_SECONDS,
    OpenLoopSettings,
    TrackPlan,
    plan_track,
)
from rhmpc.openloop.scoring import mean_rows, score
from rhmpc.openloop.tracks import Track
from rhmpc.predictors import LEARNED, needs_torch
from rhmpc.predictors.registry import torch_available

__all__ = ["SCHEMA", "estimate_lines", "run_open_loop", "run_plan", "score_track"]

#: The version of the document :func:`run_open_loop` returns (docs/guide/json.md).
SCHEMA = "rhmpc.predict.recordings/1"


def estimate_lines(plans: Sequence[TrackPlan]) -> list[str]:
    """The whole study's estimate, said before any work: the fits, then the scoring of each
    predictor (the slowest first)."""
    fitting = sum(p.fitting_s for p in plans)
    names = list(dict.fromkeys(n for p in plans for n in p.names))
    scoring = {n: sum(p.scoring_s(n) for p in plans if n in p.steps) for n in names}
    total = fitting + sum(scoring.values())
    slow = sorted((n for n in names if n in scoring), key=lambda n: -scoring[n])
    what = f"{len(plans)} track{'s' * (len(plans) != 1)}"
    return [f"about {duration(total)} in all on {what}: {duration(fitting)} of fitting, "
            f"{duration(sum(scoring.values()))} of scoring (" + ", ".join(
                f"{n} {duration(scoring[n])}" for n in slow[:6])
            + (", the others less" if len(slow) > 6 else "") + ")"]


def run_plan(plan: TrackPlan, progress: Callable[[str], None] | None = None,
             save: Path | None = None) -> tuple[dict, list[dict]]:
    """Fit ``plan``'s fitted predictors (said first) and score every predictor on its track:
    the source's description and the result rows. ``save``: a folder to write the fitted
    models to (their ``save``)."""
    fitted = _fit(plan, progress, save) if plan.fits else {}
    return score(plan, fitted, progress)


def score_track(track: Track, settings: OpenLoopSettings,
                progress: Callable[[str], None] | None = None,
                train: list[np.ndarray] | None = None,
                save: Path | None = None) -> tuple[dict, list[dict]]:
    """:func:`run_plan` of :func:`~rhmpc.openloop.recordings.plan_track`."""
    return run_plan(plan_track(track, settings, train), progress, save)


def _fit(plan: TrackPlan, progress, save: Path | None) -> dict:
    """name → (fitted predictor, seconds, cached model or None) of ``plan``'s fitted
    predictors, after their plan is said (:func:`rhmpc.experiment.fit_plan.describe`): what,
    on which frames, why in two rounds, how long, and which fitted predictors the default set
    leaves out."""
    names, period, series, leads = plan.names, plan.track.period, plan.train, plan.leads[-1]
    settings = plan.settings
    plans, where = plan.fits, plan.where
    if progress is not None:
        omitted = plan.omitted
        frames = series[0].shape[0] if len(series) == 1 else None
        for line in describe(plans, where, frames, omitted, names):
            progress(line)
    return fit_all(plans, period, series, leads, settings.seed, progress, save, plan.track.label)


def run_open_loop(tracks: Sequence[Track | list[Track]], settings: OpenLoopSettings,
                  progress: Callable[[str], None] | None = None,
                  train: Callable[[float], list[np.ndarray]] | None = None,
                  save: Path | None = None) -> dict:
    """Score every predictor on every track; a list of tracks (the points of one file) also
    gets its ``mean`` rows, labelled ``FILE:mean``.

    ``train(period)``: the recordings to fit the fitted predictors on, on the grid of
    ``period`` [s] (e.g. :func:`rhmpc.sim.recordings.training_series`); default, with a split, each
    track's samples before TRAIN. ``save``: a folder to write the fitted models to.

    Returns
    -------
    dict
        ``rate_hz`` and ``warmup_s`` (shared by every source, else ``None``), ``sources``
        (one description each), ``results`` (one row per source × predictor × lead:
        ``predictor``, ``family``, ``lead_samples``, ``lead_s``, ``rms_error_mm``,
        ``max_error_mm``, ``ratio_to_hold``, ``rejected``, ``repaired``, ``missing``,
        ``loop_lead``, ``fit_s``, ``update_us`` …), the protocol (``protocol``: ``online`` or
        ``split``, ``split``) and the rules (``warmup_rule``, ``loop_lead_rule``).
    """
    sources, results, names = [], [], []
    if progress is not None and not settings.predictors and not torch_available() and (
            train is not None or settings.split is not None):
        left = [n for n in LEARNED if needs_torch(n)]
        progress(f"{', '.join(left)} left out: they need PyTorch "
                 '(pip install "rhmpc[learned]")')
    groups = [item if isinstance(item, list) else [item] for item in tracks]
    plans = [[plan_track(track, settings, None if train is None else train(track.period),
                         progress) for track in group] for group in groups]
    if progress is not None:
        for line in estimate_lines([p for group in plans for p in group]):
            progress(line)
    for item, group in zip(tracks, plans, strict=True):
        rows_of_group = []
        for plan in group:
            source, rows = run_plan(plan, progress, save)
            sources.append(source)
            rows_of_group += rows
        results += rows_of_group
        if isinstance(item, list) and len(group) > 1:
            results += mean_rows(f"{group[0].track.label.rsplit(':', 1)[0]}:mean",
                                 rows_of_group)
    names = list(dict.fromkeys(r["predictor"] for r in results))
    rates = {round(s["rate_hz"], 9) for s in sources}
    warmups = {round(s["warmup_s"], 9) for s in sources}
    return {
        "schema": SCHEMA,
        "rate_hz": sources[0]["rate_hz"] if len(rates) == 1 else None,
        "warmup_s": sources[0]["warmup_s"] if len(warmups) == 1 else None,
        "latency_s": settings.latency, "horizon_s": settings.horizon,
        "leads": settings.leads, "predictors": names,
        "protocol": "online" if settings.split is None else "split",
        "split": None if settings.split is None else list(settings.split),
        "fitted_on": ("the training recordings" if train is not None else
                      f"frames 0–{settings.split[0] - 1}, the frames before "
                      f"{settings.split[0]}" if settings.split is not None else None),
        "seed": settings.seed,
        "warmup_rule": "split" if settings.split is not None else "given"
        if settings.warmup is not None else
        f"max({WARMUP_SECONDS:g} s, {100 * WARMUP_FRACTION:g} % of the recording)",
        "loop_lead_rule": "ceil((period + latency + horizon) / period)",
        "sources": sources, "results": results,
    }
