"""The heart rate a predictor estimates, scored against the heart's own during a run."""

from __future__ import annotations

import math
from collections.abc import Callable

__all__ = ["HeartRateScore"]


class HeartRateScore:
    """Running score of a predictor's heart-rate estimate against the true heart rate.

    At each observation after ``settling`` the error e = 60·(f̂_h − f_h(t)) [bpm] is added to
    running sums (constant memory): RMS and max of ``|e|`` and the fraction of observations with
    ``|e|`` < ``tolerance_bpm`` (5 bpm, the lock criterion). From the first observation
    on (settling included; an estimate that is not ready yet counts as unlocked) it keeps the
    "lock time": the time of the first observation after which ``|e|`` stayed below the tolerance to
    the end. ``ready_time_s`` is the first finite estimate (the EKF's initialisation window is
    Yuen's 10 s, so lock is judged from there).

    Parameters
    ----------
    true_rate : callable
        ``true_rate(t) -> f_h`` [Hz], e.g. ``PhaseTrack.rate`` of the heart source.
    settling : float
        Observations before this time [s] are not scored (the run's metric window).
    tolerance_bpm : float
        Lock tolerance [bpm].
    """

    def __init__(self, true_rate: Callable[[float], float], settling: float = 0.0,
                 tolerance_bpm: float = 5.0) -> None:
        self.true_rate, self.settling, self.tolerance = true_rate, settling, tolerance_bpm
        self.n = self.within = 0
        self.sum_sq = self.max_abs = self.sum_est = self.sum_true = 0.0
        self.lock_time: float | None = None
        self.ready_time: float | None = None

    def observe(self, t: float, estimate_hz: float) -> None:
        """Score the estimate ``estimate_hz`` [Hz] made at time ``t`` [s] (NaN: not yet)."""
        if self.ready_time is None and math.isfinite(estimate_hz):
            self.ready_time = t
        true_bpm = 60.0 * float(self.true_rate(t))
        error = abs(60.0 * estimate_hz - true_bpm) if math.isfinite(estimate_hz) else math.inf
        if error < self.tolerance:
            if self.lock_time is None:
                self.lock_time = t
        else:
            self.lock_time = None
        if t < self.settling or not math.isfinite(error):
            return
        self.n += 1
        self.sum_sq += error * error
        self.max_abs = max(self.max_abs, error)
        self.sum_est += 60.0 * estimate_hz
        self.sum_true += true_bpm
        self.within += error < self.tolerance

    def summary(self) -> dict[str, float | int | None]:
        """``rms_error_bpm``, ``max_error_bpm``, ``within_tolerance``, means, ``lock_time_s``."""
        if not self.n:
            return {"observations": 0}
        return {
            "observations": self.n,
            "rms_error_bpm": math.sqrt(self.sum_sq / self.n),
            "max_error_bpm": self.max_abs,
            "within_tolerance": self.within / self.n,
            "tolerance_bpm": self.tolerance,
            "mean_estimate_bpm": self.sum_est / self.n,
            "mean_true_bpm": self.sum_true / self.n,
            "ready_time_s": self.ready_time,
            "lock_time_s": self.lock_time,
        }
