"""The base of the predictors fitted before the run: ``fit``, ``save``/``load``, and the online
history they forecast from.

A fitted predictor learns its model from recordings first::

    p = make_predictor("st-ridge", dt=0.04)
    p.fit(series)            # one (T, P, d) array [m] on the dt grid, POI in row 0, or a list
    p.save("model.npz")      # or later: make_predictor("st-ridge", dt=0.04, model="model.npz")

and then runs on the `Predictor` contract (``update(z, others)``, ``predict(K)``); ``reset``
forgets the online history, never the fitted model. A model fitted at one sampling period
runs at that period only, on as many points as it was fitted on.

Online history.  Each update writes the row r_n = [z_n; o_n^1; …] [m] (the POI only, for a
predictor that does not read the other points). A missing POI sample is filled with the
model's own one-step forecast (its newest sample while not ready), a missing other point with
its newest sample: a model's input never holds a NaN.
"""

from __future__ import annotations

import dataclasses
import json
from abc import abstractmethod

import numpy as np

from predictors.base import Predictor
from predictors.learned.series import as_series

__all__ = ["FittedPredictor", "settings_from_json", "settings_to_json"]


def settings_to_json(settings) -> str:
    """The settings dataclass as JSON (tuples become lists)."""
    return json.dumps(dataclasses.asdict(settings), sort_keys=True)


def settings_from_json(cls, text: str):
    """The settings dataclass ``cls`` from :func:`settings_to_json`'s text (unknown keys are an
    error: the file was written by another version or another predictor)."""
    values = json.loads(text)
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - fields)
    if unknown:
        raise ValueError(f"the model file's settings {', '.join(unknown)} are not {cls.__name__}'s")
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return cls(**values)


class FittedPredictor(Predictor):
    """A predictor fitted before the run (module docstring).

    Subclasses implement ``_fit(series, progress)`` (returns the model, a dict), ``_forecast()``
    ((L, d) forecasts [m] of leads 1 … L from ``self._rows``), ``save(path)``/``_read(path)``,
    and optionally ``_advance(row)`` (a recurrent state's step) and ``_span()`` (rows kept).
    Their settings have ``leads``, ``unit`` and ``model``.
    """

    #: the file name suffix of :meth:`save`
    SUFFIX = ""

    def __init__(self, dt: float, settings=None) -> None:
        self.model: dict | None = None
        super().__init__(dt, settings)
        if self.settings.model is not None:
            self.load(self.settings.model)

    # -- before the run -----------------------------------------------------------
    @property
    def fitted(self) -> bool:
        """Whether a model has been fitted or loaded."""
        return self.model is not None

    def fit(self, series, progress=None) -> FittedPredictor:
        """Fit the model to ``series`` (module :mod:`predictors.learned.series`: (T, P, d) [m]
        on this predictor's ``dt`` grid, POI in row 0; a predictor that does not read the
        other points uses row 0 only). ``progress(text)``, if given, hears how it goes.
        Returns the predictor, its online history reset."""
        data = as_series(series, None if self.multi_point else 1)
        self.model = self._fit(data, progress)
        self.model.update(points=data[0].shape[1], dim=data[0].shape[2], dt=self.dt)
        self.reset()
        return self

    def load(self, path) -> FittedPredictor:
        """Load a model written by :meth:`save` (its settings replace this predictor's, except
        ``unit`` and ``model``). Raises ``ValueError`` for a file of another predictor or
        sampling period."""
        settings, model = self._read(path)
        if not np.isclose(model["dt"], self.dt, rtol=1e-6, atol=0.0):
            raise ValueError(f"{path}: fitted at dt = {model['dt']:g} s; this predictor runs at "
                             f"{self.dt:g} s")
        self.settings = dataclasses.replace(settings, unit=self.settings.unit, model=str(path))
        self.model = model
        self.reset()
        return self

    @abstractmethod
    def save(self, path) -> None:
        """Write the fitted model and its settings to ``path``."""

    @abstractmethod
    def _read(self, path) -> tuple[object, dict]:
        """(settings, model) from a file written by :meth:`save`."""

    @abstractmethod
    def _fit(self, series: list[np.ndarray], progress) -> dict: ...

    @abstractmethod
    def _forecast(self) -> np.ndarray:
        """(L, d) forecasts [m] of leads 1 … L from the history ``self._rows``."""

    def _advance(self, row: np.ndarray) -> None:
        """Step a recurrent state with the newest row [m] (default: nothing)."""

    def _span(self) -> int:
        """Rows of history the forecast reads."""
        return 1

    def _warmup(self) -> int:
        """Rows before the forecasts are the model's (the hold is served before)."""
        return self._span()

    # -- online -------------------------------------------------------------------
    def update(self, z, others=None) -> None:
        if self.model is None:
            raise RuntimeError(f"{type(self).__name__} is not fitted: call fit(series) or "
                               "load(path) first")
        super().update(z, others)

    def _check_layout(self, d: int) -> None:
        P = self.points if self.multi_point else 1
        if (P, d) != (self.model["points"], self.model["dim"]):
            raise ValueError(f"{type(self).__name__} was fitted on {self.model['points']} "
                             f"point(s) of dimension {self.model['dim']}; it is fed {P} of "
                             f"dimension {d}")

    def _take_others(self, others, x) -> None:
        super()._take_others(others, x)
        if self.points is not None:
            self._check_layout(self.d if self.d is not None else x.shape[0])

    def _allocate(self, d: int) -> None:
        self._check_layout(d)
        P = self.points if self.multi_point else 1
        self._rows = np.zeros((self._span(), P * d))
        self._held = np.full(P * d, np.nan)
        self._filled = 0

    def _update(self, z: np.ndarray) -> None:
        self._push(z)

    def _missing(self) -> None:
        self._push(None)

    def _push(self, z: np.ndarray | None) -> None:
        d, unit = self.d, self.unit
        row = np.empty(self._rows.shape[1])
        row[:d] = np.nan if z is None else z * unit
        if row.size > d:
            row[d:] = self.others.reshape(-1) * unit
        known = np.isfinite(row)
        if not known.all():
            fill = self._held.copy()
            if not known[:d].all() and self.ready:
                fill[:d] = self._forecast()[0]
            fill = np.where(np.isnan(fill), np.resize(fill[:d], fill.size), fill)
            row[~known] = fill[~known]
        self._held[known] = row[known]
        if np.isnan(row).any():
            return  # no POI sample yet
        self._rows[1:] = self._rows[:-1]
        self._rows[0] = row
        self._filled += 1
        self._advance(row)
        self.ready = self._filled >= self._warmup()

    def _predict(self, steps: int) -> np.ndarray:
        f = self._forecast() / self.unit
        if steps > f.shape[0]:  # beyond the fitted leads: the last one held
            f = np.vstack([f, np.repeat(f[-1:], steps - f.shape[0], axis=0)])
        return f[:steps]
