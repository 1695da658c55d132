"""Tapped delay line: the newest-first memory of past samples that feeds a transversal filter."""

from __future__ import annotations

from abc import abstractmethod
from functools import cache

import numpy as np

from rhmpc.predictors.base import Predictor

__all__ = ["DelayLinePredictor", "TappedDelayLine"]


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
    When the second measurement after a gap of g ≤ ``INTERPOLATE_GAP`` rows arrives and the two
    rows before the gap are measurements too, the fills are replaced by the cubic through those
    four samples (Lagrange interpolation at the rows' times: heart motion, ≤ 10 Hz, sampled at
    133 Hz is smooth on that scale), which is what the repair can only approximate.
    """

    #: longest gap [rows] re-interpolated by the cubic through two samples on each side
    INTERPOLATE_GAP = 3

    def __init__(self, length: int, d: int) -> None:
        self.buf = np.zeros((int(length), int(d)))
        self.filled = 0  # rows written since reset (saturates at length)
        self.real_run = 0  # consecutive measured rows at the top
        self.fills = 0  # consecutive open-loop rows at the top
        self.measured = np.zeros(int(length), dtype=bool)  # which rows are measurements

    def push(self, z: np.ndarray, measured: bool = True, expected: np.ndarray | None = None
             ) -> bool:
        """Shift by one sample and write ``z`` as the newest row.

        ``expected``: the owner's forecast of a measured ``z``; after fills it repairs them.
        Returns whether it did (the ramp; the cubic of a short gap follows a sample later).
        """
        buf = self.buf
        repaired = bool(measured and self.fills and expected is not None
                        and np.isfinite(expected).all())
        if repaired:
            g = min(self.fills, buf.shape[0] - 1)  # buf[0] is fill g, buf[g−1] fill 1
            ramp = np.arange(self.fills, self.fills - g, -1) / (self.fills + 1.0)
            buf[:g] += ramp[:, None] * (np.asarray(z) - expected)
        buf[1:] = buf[:-1]
        buf[0] = z
        self.measured[1:] = self.measured[:-1]
        self.measured[0] = measured
        self.filled = min(self.filled + 1, buf.shape[0])
        self.real_run = self.real_run + 1 if measured else 0
        self.fills = 0 if measured else self.fills + 1
        if self.real_run == 2:
            self._interpolate_gap()
        return repaired

    def _interpolate_gap(self) -> None:
        """Rows 0, 1 measured: replace a gap of g rows below them by the cubic through rows
        0, 1, g + 2, g + 3 (if those two are measurements too)."""
        flags, g = self.measured, 0
        while 2 + g < flags.shape[0] and not flags[2 + g] and g <= self.INTERPOLATE_GAP:
            g += 1
        if not 1 <= g <= self.INTERPOLATE_GAP or 3 + g >= self.filled:
            return
        if flags[2 + g : 4 + g].all():
            self.buf[2 : 2 + g] = _cubic_weights(g) @ self.buf[[0, 1, 2 + g, 3 + g]]

    def retract(self, fill: np.ndarray) -> None:
        """The newest row was an outlier: it becomes the open-loop fill ``fill``."""
        self.buf[0] = fill
        self.measured[0] = False
        self.real_run, self.fills = 0, 1


class DelayLinePredictor(Predictor):
    """A transversal-filter predictor on a :class:`TappedDelayLine` ``self.line`` of its
    ``settings.order`` = N newest samples, with its one-step forecast ``_next(past)``.

    The gap handling the line's owners share: a gap is filled open-loop with ``_next``, the
    fills are repaired when measurements return (:meth:`_push`), and the newest sample can be
    retracted (:meth:`rhmpc.predictors.base.Predictor.retract`).
    """

    @abstractmethod
    def _next(self, past: np.ndarray) -> np.ndarray:
        """ẑ (d,) of the sample after the newest-first block ``past`` (N, d)."""

    def _push(self, z: np.ndarray) -> None:
        """Push a measurement; after a gap its forecast repairs the fills (TappedDelayLine),
        counted in ``counts["repaired"]``."""
        line = self.line
        fills = line.fills and self.ready
        if line.push(z, expected=self._next(line.buf[: self.settings.order]) if fills else None):
            self.counts["repaired"] += 1

    def _missing(self) -> None:
        # run open-loop: the model's own one-step forecast fills the gap
        line = self.line
        fill = self._next(line.buf[: self.settings.order]) if self.ready else line.buf[0].copy()
        line.push(fill, measured=False)

    def _retract(self) -> bool:
        N = self.settings.order
        if self.line.real_run <= N:  # its replacement is made from N measured rows only
            return False
        self.line.retract(self._next(self.line.buf[1 : N + 1]))
        return True


@cache
def _cubic_weights(g: int) -> np.ndarray:
    """(g, 4) Lagrange weights L_j(t) = Π_{m≠j} (t − t_m)/(t_j − t_m) of the nodes
    t = 0, 1, g + 2, g + 3 at the gap's rows t = 2 … g + 1."""
    nodes = np.array([0.0, 1.0, 2.0 + g, 3.0 + g])
    at = np.arange(2.0, 2.0 + g)
    w = np.ones((g, 4))
    for j in range(4):
        for m in range(4):
            if m != j:
                w[:, j] *= (at - nodes[m]) / (nodes[j] - nodes[m])
    return w
