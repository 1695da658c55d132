"""The `Predictor` contract shared by every heart-motion predictor.

A predictor is fed one sample per period ``dt`` and forecasts the next samples
on the same grid::

    p.update(z)          # z: (d,) newest sample z_n; None / NaN / inf = missing
    p.update(z, others)  # … and the other tracked points' samples at the same instant
    p.predict(steps)     # (steps, d): ẑ_{n+1} … ẑ_{n+steps}
    p.reset()            # forget everything learnt online

Conventions:

* The dimension ``d`` is taken from the first valid sample, or from the ``dim``
  setting.  The loop feeds 3-D samples in metres, the Yuen studies 1-D.
* Units.  Parameters that the papers give in millimetres are stored in SI (m, m²)
  in the settings dataclasses.  Each dimensional predictor has a ``unit`` setting =
  metres per data unit (1.0 for samples in metres, 1e-3 for samples in millimetres)
  and converts its SI parameters to data units once: a variance σ² [m²] becomes
  σ²/unit², a gain per m² becomes gain·unit².  ``unit=None`` (the default) infers it
  from the first ``SCALE_SECONDS`` of data (:func:`rhmpc.predictors.monitor.infer_unit`,
  a power of 1000): the predictor serves the hold forecast meanwhile, then allocates
  its state and replays the window.  Fed the same motion in m or in mm, a predictor
  produces the same forecasts (×1000) either way.
* A missing sample (``None``, or any NaN/inf component) never touches the learnt
  state: the model runs open-loop through it and the event is counted in
  :attr:`Predictor.counts`.
* Numerical guards (covariance resets and bounds) are counted in
  :attr:`Predictor.counts` under the name of their reason.
* Divergence guard (every predictor): a forecast is clipped per axis to
  [lo − G·r, hi + G·r], with [lo, hi] the range of the valid samples of the last
  ``RANGE_SECONDS`` and r = hi − lo (floored at 10 % of the widest axis), G =
  ``GUARD_MULTIPLE``; clipped forecasts are counted (``forecast_clamped``).  A
  non-finite forecast is replaced by the hold forecast, the learnt state is dropped and
  relearnt from the next samples (``forecast_nonfinite``).
* ``forecast_error_rms``: the running RMS of past forecast misses at each lead, kept by
  ``update`` (the sample scored) and ``predict`` (the forecast recorded).
* Several tracked points.  ``others`` is an (P − 1, d) array of the other tracked points'
  samples at the instant of ``z`` (a row with a NaN/inf component = that point missing), or
  ``None`` when the stream has only the point of interest (POI).  A predictor that reads them
  declares ``multi_point = True`` and finds them in ``self.others`` while it absorbs the
  sample; the others ignore them.  A forecast issued after update n uses the samples ≤ n of
  every point, never a later one.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import Counter
from dataclasses import dataclass

import numpy as np

from rhmpc.predictors.monitor import LeadErrorRMS, RangeEnvelope, infer_unit

__all__ = ["Predictor", "PredictorSettings", "as_others", "as_sample", "is_measured"]


@dataclass(frozen=True)
class PredictorSettings:
    """Settings every predictor accepts.

    Attributes
    ----------
    dim : int or None
        Dimension d of a sample; ``None`` = take it from the first valid sample.
    """

    dim: int | None = None

    def __post_init__(self) -> None:
        if self.dim is not None and (int(self.dim) != self.dim or self.dim < 1):
            raise ValueError(f"dim must be a positive integer or None, got {self.dim!r}")
        unit = getattr(self, "unit", None)  # metres per data unit, where a subclass has one
        if unit is not None and not (unit > 0.0 and np.isfinite(unit)):
            raise ValueError(f"unit must be > 0 [m per data unit] or None, got {unit!r}")


def is_measured(z) -> bool:
    """Whether ``z`` is a measurement: not ``None``, every component finite and ‖z‖² too
    (‖z‖ > 1e154 is no measurement, and no gate or filter can compute with it)."""
    return z is not None and math.isfinite(float(np.vdot(z, z)))  # vdot: no FP warning


def as_sample(z, d: int | None) -> np.ndarray | None:
    """Return ``z`` as a float (d,) array, or ``None`` if it is missing (not
    :func:`is_measured`).  A sample of the wrong size raises ``ValueError`` (that is a wiring
    bug, not a dropout).
    """
    if z is None:
        return None
    x = np.array(z, dtype=float).reshape(-1)  # a copy: callers may reuse buffers
    if d is not None and x.shape[0] != d:
        raise ValueError(f"sample has {x.shape[0]} components, predictor has d={d}")
    return x if is_measured(x) else None


def as_others(others, rows: int | None, d: int | None) -> np.ndarray | None:
    """Return ``others`` as a float (rows, d) array (a copy) whose rows that are not
    :func:`is_measured` are NaN, or ``None`` for ``None``.  A shape other than (rows, d) raises
    ``ValueError`` (``rows``/``d`` ``None``: any)."""
    if others is None:
        return None
    x = np.array(others, dtype=float)
    if x.ndim != 2 or (rows is not None and x.shape[0] != rows) or (
            d is not None and x.shape[1] != d):
        want = f"({'P-1' if rows is None else rows}, {'d' if d is None else d})"
        raise ValueError(f"others has shape {x.shape}, expected {want} (one row per other point)")
    with np.errstate(over="ignore", invalid="ignore"):
        bad = ~np.isfinite(np.einsum("ij,ij->i", x, x))
    x[bad] = np.nan
    return x


class Predictor(ABC):
    """Base class: the `update`/`predict`/`reset` contract and its bookkeeping.

    Subclasses implement

    ``_allocate(d)``  allocate state once the dimension (and ``self.unit``) is known,
    ``_update(z)``    absorb a valid sample z_n (a (d,) float array, not to be kept by reference),
    ``_missing()``    advance one period open-loop (no measurement),
    ``_predict(K)``   return (K, d) forecasts ẑ_{n+1..n+K}.

    A ``multi_point`` subclass also reads ``self.others`` in ``_update`` and ``_missing``: the
    other points' samples of the same instant, (P − 1, d) with NaN rows where missing (all NaN
    when the caller passed none), P fixed by the first update (``self.points``, the stream's
    layout: ``reset`` keeps it).

    The base class validates input, infers ``d`` and the unit, counts events, guards
    forecasts against divergence, scores them per lead, and serves the *hold* forecast
    (the newest valid sample repeated) while a subclass is not yet ready (``self.ready``
    is False), e.g. during an initialisation window.

    Attributes
    ----------
    dt : float
        Sample period the predictor runs at [s].
    settings : PredictorSettings
        The frozen settings it was built with.
    d : int or None
        Sample dimension (``None`` until known).
    unit : float or None
        Metres per data unit of a dimensional predictor (``None`` until inferred, and
        always for the scale-free ones: hold, last cycle, exact).
    n : int
        Number of ``update`` calls since the last reset (valid or missing).
    counts : collections.Counter
        ``updates``, ``missing``, and the reasons of numerical guards.
    multi_point : bool
        Class attribute: whether the predictor reads the other tracked points (``others``).
    """

    Settings: type[PredictorSettings] = PredictorSettings
    #: whether ``update`` passes the other tracked points on (``self.others``)
    multi_point = False
    #: G: forecasts are clipped to G recent ranges beyond the recent [min, max] [-]
    GUARD_MULTIPLE = 2.0
    #: window of the recent signal range [s]
    RANGE_SECONDS = 2.0
    #: initialisation window of the unit inference (``unit=None``) [s]
    SCALE_SECONDS = 0.5
    #: memory of the running forecast-error RMS [s]
    ERROR_MEMORY_SECONDS = 10.0

    def __init__(self, dt: float, settings: PredictorSettings | None = None) -> None:
        dt = float(dt)
        if not np.isfinite(dt) or dt <= 0.0:
            raise ValueError(f"dt must be a positive finite number of seconds, got {dt!r}")
        self.dt = dt
        self.settings = self.Settings() if settings is None else settings
        if not isinstance(self.settings, self.Settings):
            raise TypeError(f"{type(self).__name__} takes {self.Settings.__name__}")
        self.reset()

    # -- the contract -------------------------------------------------------------
    def reset(self) -> None:
        """Forget all state learnt online and the counters (settings, ``dt``, a model fitted
        before the run and the number of tracked points are kept)."""
        self.n = 0
        self.counts: Counter[str] = Counter()
        self.ready = False
        self._last: np.ndarray | None = None
        self.d = None
        # P, the tracked points with the POI (multi-point): the stream's layout, kept by reset
        self.points: int | None = getattr(self, "points", None)
        self.others: np.ndarray | None = None
        self.unit = getattr(self.settings, "unit", None)
        infer = hasattr(self.settings, "unit") and self.unit is None
        self._pending: list | None = [] if infer else None
        self._allocated = False
        if self.settings.dim is not None:
            self._set_dim(int(self.settings.dim))

    def update(self, z: np.ndarray | None, others: np.ndarray | None = None) -> None:
        """Absorb the newest sample z_n, shape (d,); ``None``/NaN/inf = missing.

        ``others``: the other tracked points' samples at the same instant, (P − 1, d), NaN rows
        where missing, or ``None`` (read by a ``multi_point`` predictor only).
        """
        x = as_sample(z, self.d)
        if self.multi_point:
            self._take_others(others, x)
        self.n += 1
        if x is None:
            self.counts["missing"] += 1
            if self.d is not None:
                self._envelope.tick(None)
                self._absorb(None)
            return
        if self.d is None:
            self._set_dim(x.shape[0])
        self.counts["updates"] += 1
        self._last = x
        self._envelope.tick(x)
        self._errors.observe(self.n, x)
        self._absorb(x)

    def predict(self, steps: int) -> np.ndarray:
        """Forecast ẑ_{n+1} … ẑ_{n+steps} at this predictor's ``dt``; returns (steps, d)."""
        if int(steps) != steps or steps < 1:
            raise ValueError(f"steps must be a positive integer, got {steps!r}")
        steps = int(steps)
        if not self.ready:
            if self._last is None:
                raise RuntimeError(f"{type(self).__name__}: predict() before any valid sample")
            out = np.repeat(self._last[None, :], steps, axis=0)
        else:
            out = self._guard(self._predict(steps))
        self._errors.record(self.n, out)  # the latest forecast of update n (copied)
        return out

    def retract(self) -> bool:
        """Treat the newest sample as missing after the fact: it has turned out to be an outlier.

        The outlier gate (:mod:`rhmpc.control.reference`) calls it when the sample after it
        misses its forecast but agrees with the forecast made *before* the newest sample. The
        newest sample is replaced by the model's forecast of it, as if it had been missing
        (``counts["retracted"]``). Returns whether the predictor could; by default it cannot and
        nothing changes.
        """
        if self._pending is not None or not self.ready or not self._retract():
            return False
        self.counts["retracted"] += 1
        return True

    @property
    def forecast_error_rms(self) -> np.ndarray:
        """(K,) running RMS of past misses ‖ẑ_{n+k|n} − z_{n+k}‖ per lead k = 1…K [data units].

        K is the longest horizon asked of ``predict``; NaN where no forecast has been
        scored yet.  Exponentially weighted, memory ``ERROR_MEMORY_SECONDS``.
        """
        if self.d is None:
            return np.full(0, np.nan)
        return self._errors.rms()

    # -- for subclasses -----------------------------------------------------------
    def _set_dim(self, d: int) -> None:
        self.d = d
        self._envelope = RangeEnvelope(d, round(self.RANGE_SECONDS / 8 / self.dt))
        self._errors = LeadErrorRMS(d, self.ERROR_MEMORY_SECONDS / self.dt)
        self._bounds_n = -1
        self._allocate_when_known()

    def _allocate_when_known(self) -> None:
        """Allocate once d, the unit and (multi-point) the number of points are known."""
        if (not self._allocated and self.d is not None and self._pending is None
                and (self.points is not None or not self.multi_point)):
            self._allocate(self.d)
            self._allocated = True

    def _take_others(self, others, x: np.ndarray | None) -> None:
        """``self.others`` of this update, (P − 1, d) with NaN rows where missing (counted in
        ``others_missing``); P is fixed by the first update that has a dimension (a later
        mismatch raises ``ValueError``)."""
        if self.d is None and x is None:
            return  # nothing to forecast yet
        d = self.d if self.d is not None else x.shape[0]
        if self.points is None:
            self.points = 1 + (0 if others is None else as_others(others, None, d).shape[0])
        rows = self.points - 1
        if others is None:
            self.others = np.full((rows, d), np.nan)
        else:
            self.others = as_others(others, rows, d)
        lost = int(np.isnan(self.others[:, 0]).sum())
        if lost:
            self.counts["others_missing"] += lost
        self._allocate_when_known()

    def _absorb(self, x: np.ndarray | None) -> None:
        """Pass a sample (``None`` = missing) on, or keep it until the unit is known."""
        if self._pending is None:
            self._update(x) if x is not None else self._missing()
            return
        self._pending.append((self.n, x, self.others))
        if sum(v is not None for _, v, _ in self._pending) >= max(
            8, round(self.SCALE_SECONDS / self.dt)
        ):
            pending, self._pending = self._pending, None
            self.unit = infer_unit(np.array([v for _, v, _ in pending if v is not None]))
            self._allocate_when_known()
            n, others = self.n, self.others
            for self.n, v, self.others in pending:  # replay on the subclass's own clock
                self._update(v) if v is not None else self._missing()
            self.n, self.others = n, others

    def _guard(self, f: np.ndarray) -> np.ndarray:
        """Clip a forecast to the recent range (``forecast_clamped``); relearn if non-finite.

        The clipped g = min(max(f, lo), hi) tells both at once: ‖g − f‖² is > 0 where the clip
        acted, and NaN or inf where f is not finite (or so large that the square overflows:
        only then is f itself tested).
        """
        if not self._envelope.known:
            return f if np.isfinite(f).all() else self._relearn(f.shape[0])
        self._update_bounds()
        g = np.minimum(np.maximum(f, self._bounds[0]), self._bounds[1])  # np.clip: slower
        d = np.subtract(g, f)
        moved = float(np.vdot(d, d))  # vdot: no overflow warning
        if not math.isfinite(moved) and not np.isfinite(f).all():
            return self._relearn(f.shape[0])
        if moved != 0.0:  # > 0, or inf for a finite f beyond 1e154
            self.counts["forecast_clamped"] += 1
        return g

    def _relearn(self, steps: int) -> np.ndarray:
        """A non-finite forecast: learn again from scratch; hold the last sample meanwhile."""
        self.counts["forecast_nonfinite"] += 1
        self.ready = False
        self._allocate(self.d)
        return np.repeat(self._last[None, :], steps, axis=0)

    def _update_bounds(self) -> None:
        """The guard's range [lo − G·r, hi + G·r] of the recent samples, once per update."""
        if self.d is None or self._bounds_n == self.n or not self._envelope.known:
            return
        lo, hi = self._envelope.envelope()
        r = hi - lo
        r = self.GUARD_MULTIPLE * np.maximum(r, 0.1 * r[r.argmax()])
        self._bounds, self._bounds_n = (lo - r, hi + r), self.n

    def _allocate(self, d: int) -> None:  # noqa: B027 - optional hook
        """Allocate (and reset) the learnt state for dimension ``d``."""

    @abstractmethod
    def _update(self, z: np.ndarray) -> None: ...

    def _missing(self) -> None:  # noqa: B027 - optional hook
        """Advance one period without a measurement (default: nothing to do)."""

    @abstractmethod
    def _predict(self, steps: int) -> np.ndarray: ...

    def _retract(self) -> bool:
        """Replace the newest sample by the model's forecast of it; False if not possible."""
        return False

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dt={self.dt!r}, settings={self.settings!r})"
