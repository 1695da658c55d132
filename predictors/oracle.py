"""Exact reference information: the true future from the motion source (Tuna 2013, Tables I–III).

    ẑ_{n+k} = p(t_n + kΔt),   t_n = t0 + (n − 1)Δt after n calls to ``update``,

where p is ``source.position`` (float t → (d,), array t → (K, d), metres).  The
samples themselves are ignored (only counted); the clock advances one ``dt`` per
``update`` call, computed from the integer count (no floating accumulation).
``set_time(t)`` re-anchors the clock: the newest sample was taken at t.  Before the
first ``update`` the forecast starts at t0.  Cost: one ``source.position`` call per forecast.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rhmpc.predictors.base import Predictor, PredictorSettings

__all__ = ["Oracle", "OracleSettings"]


@dataclass(frozen=True)
class OracleSettings(PredictorSettings):
    """Oracle settings.

    Attributes
    ----------
    source : object
        Heart-motion source with ``position(t)`` [s → m]; required.
    t0 : float
        Time of the first sample [s].
    """

    source: Any = None
    t0: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.source is None or not callable(getattr(self.source, "position", None)):
            raise ValueError("exact: `source` must be an object with a position(t) method")


class Oracle(Predictor):
    """The true future from the heart source ("exact reference information")."""

    Settings = OracleSettings

    def reset(self) -> None:
        self._t0 = float(self.settings.t0)
        super().reset()
        if self.d is None:
            p0 = np.asarray(self.settings.source.position(self._t0), dtype=float).reshape(-1)
            self._set_dim(p0.shape[0])
        self.ready = True

    @property
    def time(self) -> float:
        """Time of the newest sample [s] (t0 − dt before the first update)."""
        return self._t0 + (self.n - 1) * self.dt

    def set_time(self, t: float) -> None:
        """Declare that the newest sample (the last ``update``) was taken at ``t`` [s]."""
        self._t0 = float(t) - (self.n - 1) * self.dt

    def _update(self, z: np.ndarray) -> None:
        pass

    def _predict(self, steps: int) -> np.ndarray:
        t = self._t0 + (self.n - 1 + np.arange(1, steps + 1)) * self.dt
        return np.asarray(self.settings.source.position(t), dtype=float).reshape(steps, self.d)
