"""Tapped delay line: the newest-first memory of past samples that feeds a transversal filter."""

from __future__ import annotations

import numpy as np

__all__ = ["TappedDelayLine"]


class TappedDelayLine:
    """Rows ``buf[0] = z_n, buf[1] = z_{n−1}, …, buf[L−1] = z_{n−L+1}``.

    ``buf[i:i+N].reshape(-1)`` is the stacked vector [z_{n−i}; …; z_{n−i−N+1}] of
    Tuna eq. (5) (a view, no copy).  ``real_run`` counts how many of the newest
    rows are measurements rather than open-loop fill-ins, so an owner can skip
    adaptation on windows that contain imputed samples.

    Gap repair.  Through a gap the owner writes its own open-loop forecasts (fills) and they
    drift from the motion; when the first measurement z after g fills arrives with the owner's
    forecast ẑ for it (``expected``), the fills are corrected by the linear ramp

        f_i ← f_i + (i/(g+1))·(z − ẑ),   i = 1 … g (oldest first),

    the conditional mean of a random-walk forecast error that starts at 0 at the last
    measurement and ends at z − ẑ (a Brownian bridge).  Without it the regressor holds a step
    between the drifted fills and the measurement, which a predictor with large, cancelling
    weights (a smooth signal extrapolated 25 ms) amplifies into a miss many times the drift.
    """

    def __init__(self, length: int, d: int) -> None:
        self.buf = np.zeros((int(length), int(d)))
        self.filled = 0  # rows written since reset (saturates at length)
        self.real_run = 0  # consecutive measured rows at the top
        self.fills = 0  # consecutive open-loop rows at the top

    def push(self, z: np.ndarray, measured: bool = True, expected: np.ndarray | None = None
             ) -> None:
        """Shift by one sample and write ``z`` as the newest row.

        ``expected``: the owner's forecast of a measured ``z``; after fills it repairs them.
        """
        buf = self.buf
        if measured and self.fills and expected is not None and np.isfinite(expected).all():
            g = min(self.fills, buf.shape[0] - 1)  # buf[0] is fill g, buf[g−1] fill 1
            ramp = np.arange(self.fills, self.fills - g, -1) / (self.fills + 1.0)
            buf[:g] += ramp[:, None] * (np.asarray(z) - expected)
        buf[1:] = buf[:-1]
        buf[0] = z
        self.filled = min(self.filled + 1, buf.shape[0])
        self.real_run = self.real_run + 1 if measured else 0
        self.fills = 0 if measured else self.fills + 1

    def retract(self, fill: np.ndarray) -> None:
        """The newest row was an outlier: it becomes the open-loop fill ``fill``."""
        self.buf[0] = fill
        self.real_run, self.fills = 0, 1
