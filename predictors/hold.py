"""Zero-order hold: ẑ_{n+k} = z_n, no prediction (the "None" row of Yuen et al. 2008, Table II)."""

from __future__ import annotations

import numpy as np

from rhmpc.predictors.base import Predictor

__all__ = ["Hold"]


class Hold(Predictor):
    """The newest valid sample, repeated; a missing sample keeps the previous one."""

    def _update(self, z: np.ndarray) -> None:
        self.ready = True

    def _predict(self, steps: int) -> np.ndarray:
        return np.repeat(self._last[None, :], steps, axis=0)
