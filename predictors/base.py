"""The `Predictor` contract shared by every heart-motion predictor.

A predictor is fed one sample per period ``dt`` and forecasts the next samples
on the same grid::

    p.update(z)          # z: (d,) newest sample z_n; None / NaN / inf = missing
    p.predict(steps)     # (steps, d): ẑ_{n+1} … ẑ_{n+steps}
    p.reset()            # forget everything learnt

Conventions (see ``../shared/DESIGN.md``):

* The dimension ``d`` is taken from the first valid sample, or from the ``dim``
  setting.  The loop feeds 3-D samples in metres, the Yuen studies 1-D.
* Units.  Parameters that the papers give in millimetres are stored in SI (m, m²)
  in the settings dataclasses.  A predictor does not know the unit of its samples,
  so each dimensional predictor has a ``unit`` setting = metres per data unit
  (1.0 for samples in metres, 1e-3 for samples in millimetres) and converts its
  SI parameters to data units once, at construction: a variance σ² [m²] becomes
  σ²/unit², a gain per m² becomes gain·unit².  With that setting a predictor fed
  the same motion in m or in mm produces the same forecasts (×1000).
* A missing sample (``None``, or any NaN/inf component) never touches the learnt
  state: the model runs open-loop through it and the event is counted in
  :attr:`Predictor.counts`.
* Numerical guards (covariance resets and bounds) are counted in
  :attr:`Predictor.counts` under the name of their reason.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import Counter
from dataclasses import dataclass

import numpy as np

__all__ = ["Predictor", "PredictorSettings", "as_sample"]


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


def as_sample(z, d: int | None) -> np.ndarray | None:
    """Return ``z`` as a float (d,) array, or ``None`` if it is missing.

    ``None`` and samples with any non-finite component are missing.  A sample of
    the wrong size raises ``ValueError`` (that is a wiring bug, not a dropout).
    """
    if z is None:
        return None
    x = np.array(z, dtype=float).reshape(-1)  # a copy: callers may reuse buffers
    if d is not None and x.shape[0] != d:
        raise ValueError(f"sample has {x.shape[0]} components, predictor has d={d}")
    if not np.isfinite(x).all():
        return None
    return x


class Predictor(ABC):
    """Base class: the `update`/`predict`/`reset` contract and its bookkeeping.

    Subclasses implement

    ``_allocate(d)``  allocate state once the dimension is known,
    ``_update(z)``    absorb a valid sample z_n (a (d,) float array, not to be kept by reference),
    ``_missing()``    advance one period open-loop (no measurement),
    ``_predict(K)``   return (K, d) forecasts ẑ_{n+1..n+K}.

    The base class validates input, infers ``d``, counts events, and serves the
    *hold* forecast (the newest valid sample repeated) while a subclass is not yet
    ready (``self.ready`` is False), e.g. during an initialisation window.

    Attributes
    ----------
    dt : float
        Sample period the predictor runs at [s].
    settings : PredictorSettings
        The frozen settings it was built with.
    d : int or None
        Sample dimension (``None`` until known).
    n : int
        Number of ``update`` calls since the last reset (valid or missing).
    counts : collections.Counter
        ``updates``, ``missing``, and the reasons of numerical guards.
    """

    Settings: type[PredictorSettings] = PredictorSettings

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
        """Forget all learnt state and counters (settings and ``dt`` are kept)."""
        self.n = 0
        self.counts: Counter[str] = Counter()
        self.ready = False
        self._last: np.ndarray | None = None
        self.d = None
        if self.settings.dim is not None:
            self._set_dim(int(self.settings.dim))

    def update(self, z: np.ndarray | None) -> None:
        """Absorb the newest sample z_n, shape (d,); ``None``/NaN/inf = missing."""
        x = as_sample(z, self.d)
        self.n += 1
        if x is None:
            self.counts["missing"] += 1
            if self.d is not None:
                self._missing()
            return
        if self.d is None:
            self._set_dim(x.shape[0])
        self.counts["updates"] += 1
        self._last = x
        self._update(x)

    def predict(self, steps: int) -> np.ndarray:
        """Forecast ẑ_{n+1} … ẑ_{n+steps} at this predictor's ``dt``; returns (steps, d)."""
        if int(steps) != steps or steps < 1:
            raise ValueError(f"steps must be a positive integer, got {steps!r}")
        steps = int(steps)
        if not self.ready:
            if self._last is None:
                raise RuntimeError(f"{type(self).__name__}: predict() before any valid sample")
            return np.repeat(self._last[None, :], steps, axis=0)
        return self._predict(steps)

    # -- for subclasses -----------------------------------------------------------
    def _set_dim(self, d: int) -> None:
        self.d = d
        self._allocate(d)

    def _allocate(self, d: int) -> None:  # noqa: B027 - optional hook
        """Allocate the state for dimension ``d`` (called once per reset)."""

    @abstractmethod
    def _update(self, z: np.ndarray) -> None: ...

    def _missing(self) -> None:  # noqa: B027 - optional hook
        """Advance one period without a measurement (default: nothing to do)."""

    @abstractmethod
    def _predict(self, steps: int) -> np.ndarray: ...

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dt={self.dt!r}, settings={self.settings!r})"
