"""Last cycle: the previous heart cycle forecasts the next (Yuen 2008; Bebek & Cavusoglu 2007).

    ẑ_{n+k} = z(t_n + kΔt − T),

with T the current cardiac period and z(·) linearly interpolated between samples
(applied repeatedly when kΔt > T: the lag is (T − k) mod T).  T is clamped to the
band's lags (at least 2 samples), so the lag is bounded by construction.  T comes from

* the signal: the lag in [1/f_max, 1/f_min] maximising the (biased) autocorrelation
  of the last ``window_seconds`` of samples, refined by a parabola, re-estimated
  every ``period_every`` seconds; or
* RR annotations when ``beat_times`` is given: T = the latest RR interval completed
  by the time of the newest sample (t = t0 + n·dt).

Breathing (``anchored`` and ``detrend``, the default parameter set ``anchored``).  Breathing
and drift move the point by z_n − z(t_n − T) in one period, and the previous cycle is reused
from where the motion is now:

    ẑ_{n+k} = z(t_n + kΔt − jT) + j·(z_n − z(t_n − T)),   j = ⌈kΔt/T⌉,

the cycle's shape from the newest sample on, the change over one period carried forward.  The
period's autocorrelation is taken of the window less its least-squares cubic in time (a 5-s
window holds less than one 6-s breath, which a cubic follows); breathing otherwise dominates
it, and its maximum sits at the shortest lag of the band.  ``yuen2008`` is the plain last
cycle of Yuen et al. 2008 §III-D (``benchmarks/invivo_regime.py`` measures both).

A missing sample is filled with its own forecast (open loop).  Until a period is
known the forecast holds the newest sample.  Cost per update: O(1), plus an
O(W log W) FFT every ``period_every`` seconds (W samples in the window).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.predictors.base import Predictor, PredictorSettings

__all__ = ["PARAMETER_SETS", "LastCycle", "LastCycleSettings"]


@dataclass(frozen=True)
class LastCycleSettings(PredictorSettings):
    """Last-cycle settings.

    Attributes
    ----------
    window_seconds : float
        History used to estimate the period [s]; at least two slowest periods.
    period_every : float
        Re-estimation interval of the period [s].
    band_hz : tuple of float
        Heart-rate band [Hz]: lags between 1/high and 1/low.
    beat_times : tuple of float or None
        R-peak times [s] on the predictor's clock (t0 + n·dt); if given, T is the RR interval.
    t0 : float
        Time of the first sample [s] (only used with ``beat_times``).
    anchored : bool
        Reuse the cycle from the newest sample, carrying the change over one period forward
        (module docstring); False: the previous cycle as it was (Yuen).
    detrend : bool
        Estimate the period on the window less its least-squares cubic in time.
    """

    window_seconds: float = 5.0
    period_every: float = 0.5
    band_hz: tuple[float, float] = (0.5, 2.5)
    beat_times: tuple[float, ...] | None = None
    t0: float = 0.0
    anchored: bool = False
    detrend: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        lo, hi = self.band_hz
        if not 0.0 < lo < hi:
            raise ValueError("band_hz must be (low, high) with 0 < low < high [Hz]")
        if not self.window_seconds >= 2.0 / lo:
            raise ValueError(f"window_seconds must be >= 2/band_hz[0] = {2.0 / lo} s")
        if not self.period_every > 0.0:
            raise ValueError("period_every must be > 0 [s]")
        if self.beat_times is not None:
            bt = np.asarray(self.beat_times, dtype=float)
            if bt.ndim != 1 or bt.size < 2 or np.any(np.diff(bt) <= 0):
                raise ValueError("beat_times must be >= 2 increasing times [s]")


#: Parameter sets: ``yuen2008`` (the previous cycle as it was, Yuen et al. 2008 §III-D) and
#: ``anchored`` (the default: breathing removed, module docstring).
PARAMETER_SETS: dict[str, LastCycleSettings] = {
    "yuen2008": LastCycleSettings(),
    "anchored": LastCycleSettings(anchored=True, detrend=True),
}


class LastCycle(Predictor):
    """Previous-cycle predictor; period from the autocorrelation or from RR annotations."""

    Settings = LastCycleSettings
    PRESETS = PARAMETER_SETS

    def _allocate(self, d: int) -> None:
        s = self.settings
        self.L = int(np.ceil(s.window_seconds / self.dt)) + 2
        self.filled = 0
        self.period = np.nan  # in samples
        self._every = max(1, round(s.period_every / self.dt))
        lo = max(2, int(np.floor(1.0 / (s.band_hz[1] * self.dt))))
        self._lags = (lo, max(lo + 2, int(np.ceil(1.0 / (s.band_hz[0] * self.dt)))))
        self.L = max(self.L, 2 * self._lags[1] + 3)
        self.hist = np.zeros((self.L, d))  # newest first
        self._beats = None if s.beat_times is None else np.asarray(s.beat_times, dtype=float)

    def _push(self, z: np.ndarray) -> None:
        self.hist[1:] = self.hist[:-1]
        self.hist[0] = z
        self.filled = min(self.filled + 1, self.L)

    def _update(self, z: np.ndarray) -> None:
        self._push(z)
        if self._beats is not None:
            t = self.settings.t0 + (self.n - 1) * self.dt
            i = np.searchsorted(self._beats, t, side="right")
            if i >= 2:
                self.period = self._in_band((self._beats[i - 1] - self._beats[i - 2]) / self.dt)
        elif self.filled >= min(self.L, 2 * self._lags[1] + 1) and self.n % self._every == 0:
            self.period = self._in_band(self._estimate_period())
        self.ready = np.isfinite(self.period) and self.period + 1 < self.filled

    def _in_band(self, T: float) -> float:
        """T clamped to the band's lags [samples] (counted ``period_clamped``)."""
        lo, hi = self._lags
        if not lo <= T <= hi:
            self.counts["period_clamped"] += 1
            T = float(np.clip(T, lo, hi)) if np.isfinite(T) else float(hi)
        return T

    def _estimate_period(self) -> float:
        x = self.hist[: self.filled][::-1]
        if self.settings.detrend:  # less a cubic in time: the breathing over the window
            t = np.linspace(-1.0, 1.0, len(x))
            V = np.vander(t, 4)
            x = x - V @ np.linalg.lstsq(V, x, rcond=None)[0]
        x = x - x.mean(axis=0)
        W = x.shape[0]
        nfft = int(2 ** np.ceil(np.log2(2 * W)))
        X = np.fft.rfft(x, n=nfft, axis=0)
        ac = np.fft.irfft((X * X.conj()).real.sum(axis=1), n=nfft)[:W]
        lo, hi = self._lags
        hi = min(hi, W - 2)
        if hi <= lo:
            return self.period
        k = lo + int(np.argmax(ac[lo : hi + 1]))
        a, b, c = ac[k - 1], ac[k], ac[k + 1]
        den = a - 2 * b + c
        return k + (float(np.clip(0.5 * (a - c) / den, -1.0, 1.0)) if den < 0 else 0.0)

    def _missing(self) -> None:
        self._push(self._predict(1)[0] if self.ready else self.hist[0].copy())

    def _value_at(self, back: float) -> np.ndarray:
        """z at ``back`` samples before the newest one (fractional, linear interpolation)."""
        i = int(np.floor(back))
        f = back - i
        i = min(i, self.filled - 2)
        return (1 - f) * self.hist[i] + f * self.hist[i + 1]

    def _predict(self, steps: int) -> np.ndarray:
        T = self.period
        out = np.empty((steps, self.d))
        shift = self.hist[0] - self._value_at(T) if self.settings.anchored else 0.0
        for k in range(1, steps + 1):
            out[k - 1] = self._value_at((T - k) % T) + np.ceil(k / T) * shift  # in [0, T)
        return out
