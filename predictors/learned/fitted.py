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
import warnings
from abc import abstractmethod

import numpy as np

from rhmpc.io import FileError
from rhmpc.predictors.base import Predictor
from rhmpc.predictors.learned.modelfile import ModelFile, write_model
from rhmpc.predictors.learned.series import as_series

__all__ = ["MIN_FIT_SECONDS", "FitWarning", "FittedPredictor", "settings_from_dict"]

#: The least measured time [s] a network is fitted on without a :class:`FitWarning`: five
#: beats at 60 beats/min, the least that shows the beat-to-beat variation a model must learn.
MIN_FIT_SECONDS = 5.0


class FitWarning(UserWarning):
    """A predictor was fitted, but on too little data for its forecasts to be trusted."""


def settings_from_dict(cls, values: dict, where: str):
    """The settings dataclass ``cls`` from a model file's ``settings`` (lists become tuples);
    unknown keys and invalid values are a :class:`rhmpc.io.FileError` naming ``where``."""
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - fields)
    if unknown:
        raise FileError(f"{where}: the model's settings {', '.join(unknown)} are not "
                        f"{cls.__name__}'s")
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise FileError(f"{where}: the model's settings: {exc}") from None


class FittedPredictor(Predictor):
    """A predictor fitted before the run (module docstring).

    Subclasses implement ``_fit(series, progress)`` (returns the model, a dict), ``_forecast()``
    ((L, d) forecasts [m] of leads 1 … L from ``self._rows``), and the model's file:
    ``_arrays()`` (what :meth:`save` writes), ``model_shapes(settings, saved)`` (the arrays a
    file of these settings holds) and ``_restore(settings, arrays, saved)`` (the model from
    them); optionally ``_advance(row)`` (a recurrent state's step) and ``_span()`` (rows kept).
    Their settings have ``leads``, ``unit`` and ``model``.
    """

    #: the predictor's name (``rhmpc.predictors.registry.LEARNED``), the ``kind`` of its files
    KIND = ""
    #: the file name suffix of :meth:`save`
    SUFFIX = ".npz"

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
        """Fit the model to ``series`` (module :mod:`rhmpc.predictors.learned.series`: (T, P, d) [m]
        on this predictor's ``dt`` grid, POI in row 0; a predictor that does not read the
        other points uses row 0 only). ``progress(text)``, if given, hears how it goes.
        Returns the predictor, its online history reset."""
        data = as_series(series, None if self.multi_point else 1)
        self._warn_if_short(data)
        self.model = self._fit(data, progress)
        self.model.update(points=data[0].shape[1], dim=data[0].shape[2], dt=self.dt)
        self.reset()
        return self

    def _warn_if_short(self, series: list[np.ndarray]) -> None:
        """A :class:`FitWarning` when the series hold less than :data:`MIN_FIT_SECONDS` of
        samples whose point of interest was measured."""
        measured = sum(int(np.isfinite(a[:, 0]).all(axis=1).sum()) for a in series)
        if measured * self.dt < MIN_FIT_SECONDS:
            warnings.warn(f"{self.KIND or type(self).__name__} is fitted on {measured} "
                          f"samples ({measured * self.dt:.3g} s), less than "
                          f"{MIN_FIT_SECONDS:g} s: its forecasts rest on fewer than five "
                          "beats; give it more data (a longer --split TRAIN, --train "
                          "recordings, a longer settling)", FitWarning, stacklevel=3)

    def load(self, path) -> FittedPredictor:
        """Load a model written by :meth:`save`, checked before any array is read
        (:class:`~rhmpc.predictors.learned.modelfile.ModelFile`); its settings replace this
        predictor's, except ``unit`` and ``model``.

        Raises
        ------
        ValueError
            (:class:`rhmpc.io.FileError`) Naming the file: not a model of this predictor, of
            another sampling period, damaged, altered or too large.
        """
        with ModelFile(path, self.KIND) as saved:
            settings = settings_from_dict(self.Settings, saved.settings, str(path))
            if not np.isclose(saved.dt, self.dt, rtol=1e-6, atol=0.0):
                raise FileError(f"{path}: fitted at dt = {saved.dt:g} s; this predictor runs "
                                f"at {self.dt:g} s")
            saved.expect(*self.model_shapes(settings, saved))
            model = self._restore(settings, saved.arrays(), saved)
        model.update(points=saved.points, dim=saved.dim, dt=saved.dt)
        self.settings = dataclasses.replace(settings, unit=self.settings.unit, model=str(path))
        self.model = model
        self.reset()
        return self

    def save(self, path) -> None:
        """Write the fitted model and its settings to ``path`` (the one model format,
        :mod:`rhmpc.predictors.learned.modelfile`; atomically, never through a link)."""
        if self.model is None:
            raise RuntimeError(f"{type(self).__name__} is not fitted: nothing to save")
        m = self.model
        write_model(path, self.KIND, m["dt"], m["points"], m["dim"], self.settings,
                    self._arrays())

    @abstractmethod
    def _arrays(self) -> dict[str, np.ndarray]:
        """The fitted model's arrays, by name (what :meth:`save` writes)."""

    @abstractmethod
    def model_shapes(self, settings, saved: ModelFile
                     ) -> tuple[dict[str, tuple[int, ...]], tuple[str, ...]]:
        """(name → shape of every array a file of ``settings`` holds, names of the optional
        ones), from the file's header ``saved`` (points, dim; small arrays may be read),
        computed without allocating the model."""

    @abstractmethod
    def _restore(self, settings, arrays: dict[str, np.ndarray], saved: ModelFile) -> dict:
        """The model (a dict) from a checked file's ``arrays``."""

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
