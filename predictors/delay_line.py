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
    """

    def __init__(self, length: int, d: int) -> None:
        self.buf = np.zeros((int(length), int(d)))
        self.filled = 0  # rows written since reset (saturates at length)
        self.real_run = 0  # consecutive measured rows at the top

    def push(self, z: np.ndarray, measured: bool = True) -> None:
        """Shift by one sample and write ``z`` as the newest row."""
        buf = self.buf
        buf[1:] = buf[:-1]
        buf[0] = z
        self.filled = min(self.filled + 1, buf.shape[0])
        self.real_run = self.real_run + 1 if measured else 0
