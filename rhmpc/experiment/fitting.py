"""Predictors that learn before the run, in a closed-loop run: what they are fitted on.

A predictor with ``fit`` (:mod:`rhmpc.predictors.learned`, or a combination with such members)
learns from series on its own sampling grid, (T, P, d) [m] with the POI first
(:mod:`rhmpc.predictors.learned.series`). In a run it is fitted, before the first tick, on

- the samples it will itself read during the run's settling window, exactly as the loop will
  give them (:class:`rhmpc.sim.loop.closed_loop.Refreshes`: the predictor's clock, its gaps, the
  other tracked points of a recording), in the sensor's frame as the loop gives them; the metrics
  start after that window, so no scored sample is ever in the training;
- and the recordings of ``RunConfig.train``, read as the run's own (the same POI), each in its
  own frame, as the open-loop study fits on them; they must be sampled at the predictor's
  period.

Fitted here or open loop (``rhmpc predict --save-models``, loaded with ``--model``), a model
sees the same samples in the loop: the loop hands the predictor the samples as measured. A
model fitted on the same samples before, by a run or by ``rhmpc predict``, is loaded from the
cache instead of fitted again (:mod:`rhmpc.experiment.model_cache`), and a new fit is kept
there.
"""

from __future__ import annotations

import contextlib

import numpy as np

from rhmpc.errors import UsageError
from rhmpc.experiment.fit_plan import describe, plan_fits
from rhmpc.experiment.model_cache import fit_or_load, lookup, store
from rhmpc.predictors.registry import LEARNED, model_kind
from rhmpc.sim.loop.closed_loop import Refreshes
from rhmpc.sim.recordings import RecordingError
from rhmpc.sim.recordings.points import training_series

__all__ = ["fit_predictor", "model_settings", "settling_series", "with_models"]


def needs_fit(predictor) -> bool:
    """Whether ``predictor`` learns before the run and has not (``fit``, not ``fitted``)."""
    return hasattr(predictor, "fit") and not getattr(predictor, "fitted", False)


def fit_predictor(run, progress=None) -> None:
    """Fit the run's predictor on its settling window and ``run.config.train`` (module
    docstring), when it learns before the run and was not loaded from saved models; a
    combination then scores its members after the settling window only."""
    predictor = getattr(run.reference, "predictor", None)
    if predictor is None or not hasattr(predictor, "fit"):
        return
    settling = settling_series(run)
    if needs_fit(predictor):
        _fit(run, predictor, settling, progress)
    if hasattr(predictor, "score_after"):  # a combination: its members learnt the settling
        predictor.score_after(settling.shape[0])


def _fit(run, predictor, settling: np.ndarray, progress) -> None:
    """Fit ``predictor`` on the settling window ``settling`` and the training recordings."""
    series = [settling, *training_recordings(run.config, predictor.dt)]
    series = [s for s in series if np.isfinite(s[:, 0]).any()]
    if not series and hasattr(predictor, "score_after"):  # a combination: its online members
        if progress is not None:
            progress(f"{run.config.predictor}: nothing before the run to fit its fitted "
                     "members on; it runs the others")
        return
    if not series:
        raise UsageError(f"{run.config.predictor} learns before the run and has nothing to "
                         "learn from: give it a settling window (loop.settling) or --train "
                         "recordings")
    if progress is not None:
        for line in announcement(run.config.predictor, predictor, series, run.config.seed):
            progress(line)
    try:
        _fit_or_load(predictor, series, progress)
    except ValueError as exc:
        raise UsageError(f"fitting {run.config.predictor}: {exc}") from None


def _fit_or_load(predictor, series: list[np.ndarray], progress) -> None:
    """Fit ``predictor`` (a combination: its members that learn before the run) on ``series``,
    each model loaded from the cache where it was fitted on them before, and kept there after
    its fit (:mod:`rhmpc.experiment.model_cache`)."""
    if not hasattr(predictor, "members"):
        fit_or_load(predictor, series, progress)
        return
    todo = [m for m in predictor.members if needs_fit(m)]
    for m in todo:
        if (path := lookup(m, series)) is not None:
            with contextlib.suppress(OSError, ValueError):  # unreadable: fitted below
                m.load(path)
    predictor.fit(series, progress)
    for m in todo:
        if getattr(m, "fitted", False) and not m.settings.model:
            store(m, series)


def announcement(name: str, predictor, series: list[np.ndarray], seed: int) -> list[str]:
    """What the run's predictor ``name`` (or its members) fits on ``series`` before the run,
    why in two rounds, and about how long it will take (:mod:`rhmpc.experiment.fit_plan`: each
    network predictor timed from a few epochs of one network on these samples)."""
    names, models = (predictor.settings.members, predictor.members) \
        if hasattr(predictor, "members") else ((name,), (predictor,))
    todo = {n: m for n, m in zip(names, models, strict=True) if needs_fit(m)}
    leads = max((getattr(m.settings, "leads", 1) for m in todo.values()), default=1)
    plans = plan_fits(list(todo), predictor.dt, series, leads, seed, todo)
    frames = sum(s.shape[0] for s in series)
    return describe(plans, f"{frames} samples ({len(series)} series) before the run",
                    series[0].shape[0] if len(series) == 1 else None)


def with_models(config, files, strict: bool = True):
    """``config`` whose predictor loads the saved models ``files`` (:func:`model_settings`)."""
    changes = model_settings(config, files, strict)
    return config.replace(**changes) if changes else config


def model_settings(config, files, strict: bool = True) -> dict:
    """The settings with which the predictor of ``config`` loads the saved models ``files``
    (``rhmpc predict --save-models``; each declares its kind) instead of fitting before the
    run: a predictor fitted before the run takes the file of its kind
    (``predictor_settings.model``), a combination each file into its member of that kind
    (``predictor_settings.models``).

    ``strict``: a predictor that takes none of the files, or a file of another kind, is a
    one-line ``UsageError`` (``simulate``); otherwise such a run is left as it is (``compare``,
    where each row takes what is its own).
    """
    if not files:
        return {}
    name = config.predictor
    try:
        kinds = [model_kind(f) for f in files]
    except (ValueError, ImportError) as exc:
        raise UsageError(str(exc)) from None
    if name == "combination":
        return {"predictor_settings.models": [str(f) for f in files]}
    mine = [str(f) for f, kind in zip(files, kinds, strict=True) if kind == name]
    if strict and (name not in LEARNED or len(mine) != len(files)):
        what = (f"{name} takes one {name} model" if name in LEARNED else
                f"{name} is not fitted before the run (models are for "
                f"{', '.join(LEARNED)} and the combination)")
        given = ", ".join(f"{f} ({k})" for f, k in zip(files, kinds, strict=True))
        raise UsageError(f"--model: {what}; given {given}")
    if strict and len(mine) > 1:
        raise UsageError(f"--model: {name} takes one model, given {len(mine)}")
    return {"predictor_settings.model": mine[0]} if mine else {}


def settling_series(run) -> np.ndarray:
    """(T, P, d) [m]: what the predictor reads during the settling window, one row per
    refresh (NaN where a sample or a point is missing), the POI first."""
    loop = run.config.loop
    refreshes = Refreshes(run.stream, loop, run.clock, run.points)
    P = 1 if run.points is None else 1 + run.points.others.shape[1]
    rows = []
    for tick in range(round(loop.settling_s / loop.Ts)):
        for z, _, others in refreshes.due(tick):
            row = np.full((P, 3), np.nan)
            if z is not None:
                row[0] = z
            if others is not None:
                row[1:] = others
            rows.append(row)
    return np.array(rows).reshape(-1, P, 3)


def training_recordings(config, period: float) -> list[np.ndarray]:
    """The recordings of ``config.train`` as (T, P, d) [m] on their grid, POI first, each
    in its own frame (:func:`rhmpc.sim.recordings.training_series`)."""
    if not config.train:
        return []
    read = dict(config.data_read)
    poi = read.pop("point", None)
    try:
        series = training_series(config.train, poi, read, period)
    except RecordingError as exc:
        raise UsageError(f"--train: {exc}") from None
    return series
