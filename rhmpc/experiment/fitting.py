"""Predictors that learn before the run, in a closed-loop run: what they are fitted on.

A predictor with ``fit`` (:mod:`predictors.learned`, or a combination with such members) learns
from series on its own sampling grid, (T, P, d) [m] with the POI first
(:mod:`predictors.learned.series`). In a run it is fitted, before the first tick, on

- the samples it will itself read during the run's settling window, exactly as the loop will
  give them (:class:`sim.loop.closed_loop.Refreshes`: the predictor's clock, its gaps, the other
  tracked points of a recording), centred as the loop centres them; the metrics start after
  that window, so no scored sample is ever in the training;
- and the recordings of ``RunConfig.train``, read as the run's own (the same POI), each centred
  on its POI's mean; they must be sampled at the predictor's period.
"""

from __future__ import annotations

import numpy as np

from rhmpc.errors import UsageError
from sim.loop.closed_loop import Refreshes
from sim.recordings import RecordingError
from sim.recordings.points import training_series

__all__ = ["fit_predictor", "settling_series"]


def needs_fit(predictor) -> bool:
    """Whether ``predictor`` learns before the run and has not (``fit``, not ``fitted``)."""
    return hasattr(predictor, "fit") and not getattr(predictor, "fitted", False)


def fit_predictor(run, progress=None) -> None:
    """Fit the run's predictor on its settling window and ``run.config.train`` (module
    docstring), when it learns before the run; nothing otherwise."""
    predictor = getattr(run.reference, "predictor", None)
    if predictor is None or not needs_fit(predictor):
        return
    settling = settling_series(run)
    series = [settling, *training_recordings(run.config, predictor.dt)]
    series = [s for s in series if np.isfinite(s[:, 0]).any()]
    if not series:
        raise UsageError(f"{run.config.predictor} learns before the run and has nothing to "
                         "learn from: give it a settling window (loop.settling) or --train "
                         "recordings")
    if progress is not None:
        frames = sum(s.shape[0] for s in series)
        progress(f"fitting {run.config.predictor} on {frames} samples "
                 f"({len(series)} series) before the run")
    try:
        predictor.fit(series, progress)
    except ValueError as exc:
        raise UsageError(f"fitting {run.config.predictor}: {exc}") from None
    if hasattr(predictor, "score_after"):  # a combination: its members learnt the settling
        predictor.score_after(settling.shape[0])


def settling_series(run) -> np.ndarray:
    """(T, P, d) [m]: what the predictor reads during the settling window, one row per
    refresh (NaN where a sample or a point is missing), the POI first."""
    loop = run.config.loop
    refreshes = Refreshes(run.stream, run.truth.center, loop, run.clock, run.points)
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
    centred on its POI's mean (:func:`sim.recordings.training_series`)."""
    if not config.train:
        return []
    read = dict(config.data_read)
    poi = read.pop("point", None)
    try:
        series = training_series(config.train, poi, read, period)
    except RecordingError as exc:
        raise UsageError(f"--train: {exc}") from None
    return [s - np.nanmean(s[:, 0], axis=0) for s in series]
