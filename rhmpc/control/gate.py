"""Innovation gating of sensor samples against the predictor's one-step forecast.

A sample whose miss e = z − ẑ (ẑ the forecast made for it one period earlier) exceeds the gate
is treated as missing: the heart cannot jump millimetres between two samples, an echo outlier
can. The rule, its unlocking and the retraction that uses it are described in
:mod:`rhmpc.control.reference`; the floor's choice is a design decision (outlier gate).
"""

from __future__ import annotations

import math

import numpy as np


class OutlierGate:
    """Innovation gate on sensor samples (see the module docstring for the rule).

    Parameters
    ----------
    gate : float or None
        Smallest gate radius, the floor [m]; the radius is max(floor, 4·e_rms). None: the floor
        is calibrated on the data: every sample is accepted during the first 2 × ``calibration``
        misses; the first half lets the predictor converge (an RLS predictor's one-step miss
        falls by 2–4× over its first seconds), and on the second half floor = 4·√(mean ‖e‖²)
        over the misses no larger than 5 × their median (an outlier in the window does not
        widen the gate).
    max_rejections : int
        Consecutive rejections after which the gate unlocks.
    relock : int
        Consecutive samples inside the gate after which an unlocked gate locks again.
    calibration : int
        Misses the floor is calibrated on (``gate`` None) [samples].
    """

    #: The smallest calibrated floor [m] (a noise-free signal would give 0).
    MIN_FLOOR = 1e-6

    def __init__(self, gate: float | None, max_rejections: int = 2, relock: int = 20,
                 calibration: int = 100) -> None:
        if gate is not None and not (math.isfinite(gate) and gate > 0):
            raise ValueError("the gate must be > 0 [m] (or None: calibrated on the data)")
        if max_rejections < 0 or relock < 1 or calibration < 1:
            raise ValueError("max_rejections must be >= 0, relock and calibration >= 1")
        self.gate, self.max_rejections, self.relock = gate, max_rejections, relock
        self.calibration = calibration
        self.reset()

    def reset(self) -> None:
        self.locked = True
        self._rejected = 0  # consecutive rejections (locked)
        self._inside = 0  # consecutive samples inside the gate (unlocked)
        self._miss2 = 0.0  # e_rms², over accepted samples
        self._calibrating: list[float] | None = [] if self.gate is None else None
        self.floor = self.gate  # [m]; None while calibrating
        self._threshold2 = 0.0 if self.gate is None else self.gate**2

    @staticmethod
    def miss2(z: np.ndarray, forecast: np.ndarray) -> float:
        """‖z − ẑ‖² [m²], what :meth:`inside` and :meth:`accept` judge."""
        miss = z - forecast
        return float(np.dot(miss, miss))

    def inside(self, z: np.ndarray, forecast: np.ndarray, miss2: float | None = None) -> bool:
        """Whether a locked gate would accept ``z`` against ``forecast`` (no state changes);
        ``miss2``: :meth:`miss2` of the two, if the caller has it."""
        if self._calibrating is not None:
            return True
        miss2 = self.miss2(z, forecast) if miss2 is None else miss2
        return self.locked and miss2 <= self._threshold2

    def accept(self, z: np.ndarray, forecast: np.ndarray, counts,
               miss2: float | None = None) -> bool:
        """Whether sample ``z`` is accepted given its ``forecast``; events go to ``counts``;
        ``miss2``: :meth:`miss2` of the two, if the caller has it."""
        miss2 = self.miss2(z, forecast) if miss2 is None else miss2
        if self._calibrating is not None:
            self._calibrate(miss2)
        else:
            outside = miss2 > self._threshold2
            if not self.locked:
                self._inside = 0 if outside else self._inside + 1
                self.locked = self._inside >= self.relock
            elif not outside:
                self._rejected = 0
            elif self._rejected < self.max_rejections:
                self._rejected += 1
                counts["outliers_rejected"] += 1
                return False
            else:
                self.locked, self._rejected, self._inside = False, 0, 0
                counts["gate_unlocked"] += 1
        self._miss2 += 0.02 * (miss2 - self._miss2)
        self._threshold2 = max(self.floor**2 if self.floor else 0.0, 16.0 * self._miss2)
        return True

    def _calibrate(self, miss2: float) -> None:
        """Collect a squared miss; after 2 × ``calibration`` of them, set the floor."""
        self._calibrating.append(miss2)
        if len(self._calibrating) >= 2 * self.calibration:
            e = np.sqrt(np.asarray(self._calibrating[self.calibration :]))
            kept = e[e <= 5.0 * np.median(e)]
            self.floor = max(4.0 * float(np.sqrt(np.mean(kept**2))), self.MIN_FLOOR)
            self._calibrating = None
