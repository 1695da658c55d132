"""Statistics of a motion record: peak-to-peak, RMS, power spectrum and its peaks.

Definitions used throughout the project for heart-motion data:

* peak-to-peak: the largest per-axis range, max_d (max_t p_d(t) − min_t p_d(t));
* RMS: the 3-D RMS about the mean, √(mean_t ‖p(t) − p̄‖²);
* PSD: Welch's estimate per axis, Hann window, mean removed; the NaN samples of a recording
  are replaced by linear interpolation for the spectrum only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.sim.heart.motion import MotionSource


def peak_to_peak(p: np.ndarray) -> float:
    """max_d (max p_d − min p_d) over the finite samples of ``p`` (n, dim) [same unit as p]."""
    p = np.asarray(p, dtype=float).reshape(len(p), -1)
    return float(np.max(np.nanmax(p, axis=0) - np.nanmin(p, axis=0)))


def rms_about_mean(p: np.ndarray) -> float:
    """√(mean_t ‖p − p̄‖²) over the finite rows of ``p`` (n, dim)."""
    p = np.asarray(p, dtype=float).reshape(len(p), -1)
    p = p[np.all(np.isfinite(p), axis=1)]
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


def fill_gaps(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``p`` (n, dim) with NaN samples replaced by linear interpolation in ``t``."""
    p = np.array(p, dtype=float).reshape(len(p), -1)
    for d in range(p.shape[1]):
        ok = np.isfinite(p[:, d])
        if ok.any() and not ok.all():
            p[~ok, d] = np.interp(t[~ok], t[ok], p[ok, d])
    return p


def psd(p: np.ndarray, rate: float, resolution: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Welch PSD per axis: ``(f [Hz], S (n_f, dim) [unit²/Hz])``.

    Segments are 1/``resolution`` seconds long (or the whole record), Hann window, 50 % overlap.
    """
    p = np.asarray(p, dtype=float).reshape(len(p), -1)
    nper = min(len(p), round(rate / resolution))
    from scipy import signal  # imported here: scipy.signal costs ~1 s of start-up

    f, s = signal.welch(p, fs=rate, nperseg=nper, detrend="constant", axis=0)
    return f, s


def spectral_peaks(f: np.ndarray, s: np.ndarray, fmin: float = 0.05, fmax: float = 30.0,
                   count: int = 8, prominence: float = 1.0) -> np.ndarray:
    """Frequencies [Hz] of the strongest local maxima of the summed PSD in ``[fmin, fmax]``.

    A peak must stand ``prominence`` decades above its surroundings (on log₁₀ S). Returns at
    most ``count`` frequencies, strongest first.
    """
    total = np.sum(np.reshape(s, (len(f), -1)), axis=1)
    band = (f >= fmin) & (f <= fmax)
    fb, logs = f[band], np.log10(np.maximum(total[band], 1e-300))
    from scipy import signal

    idx, _ = signal.find_peaks(logs, prominence=prominence)
    order = np.argsort(logs[idx])[::-1][:count]
    return fb[idx[order]]


#: The band searched for the heart rate of a recording [Hz] (42–210 beats/min).
HEART_BAND = (0.7, 3.5)
#: A recording's heart rate is estimated only from at least this many of the band's slowest
#: periods of complete samples [-].
MIN_BEATS = 2.0


def spectral_heart_rate(f: np.ndarray, s: np.ndarray) -> float:
    """The frequency [Hz] of the largest summed PSD ``s`` (n_f, dim) in :data:`HEART_BAND`;
    NaN if the band holds no frequency or its power is not finite (overflowing samples)."""
    band = (f >= HEART_BAND[0]) & (f <= HEART_BAND[1])
    power = np.sum(np.reshape(s, (len(f), -1))[band], axis=1)
    if not band.any() or not np.all(np.isfinite(power)):
        return float("nan")
    return float(f[band][np.argmax(power)])


def heart_rate_track(t: np.ndarray, p: np.ndarray, rate: float, window: float = 10.0,
                     hop: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """The heart rate of a recording over time: the spectral peak in :data:`HEART_BAND` of
    each ``window``-second stretch, ``hop`` seconds apart (Hann window, mean removed, the
    spectrum zero-padded to 0.01 Hz bins).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Regular sample times [s].
    p : ndarray, shape (n, dim)
        Positions, gaps already filled (:func:`fill_gaps`).
    rate : float
        Sample rate [Hz].
    window, hop : float
        Length of a stretch and the step between stretches [s].

    Returns
    -------
    (ndarray, ndarray)
        The stretches' centre times [s] and heart rates [Hz]; empty when the record is
        shorter than one window.
    """
    p = np.asarray(p, dtype=float).reshape(len(p), -1)
    size, step = round(window * rate), max(1, round(hop * rate))
    if size < 2 or size > len(p):
        return np.zeros(0), np.zeros(0)
    nfft = max(size, 1 << int(np.ceil(np.log2(rate / 0.01))))
    f = np.fft.rfftfreq(nfft, 1.0 / rate)
    taper = np.hanning(size)[:, None]
    starts = np.arange(0, len(p) - size + 1, step)
    rates = np.empty(starts.size)
    for i, a in enumerate(starts):
        x = p[a:a + size]
        power = np.abs(np.fft.rfft((x - x.mean(axis=0)) * taper, n=nfft, axis=0)) ** 2
        rates[i] = spectral_heart_rate(f, power)
    return t[starts + size // 2], rates


@dataclass(frozen=True)
class MotionStats:
    """Summary of a motion record.

    Attributes
    ----------
    peak_to_peak : float
        Largest per-axis range [m].
    rms : float
        3-D RMS about the mean [m].
    rms_per_axis : tuple of float
        Per-axis RMS about the mean [m].
    heart_rate : tuple of float
        (min, max) heart rate [Hz]; from the heart phase when the source has one, else the
        strongest spectral peak in :data:`HEART_BAND` (min = max), NaN when the complete
        samples last less than :data:`MIN_BEATS` periods of the band's slowest rate or the
        spectrum is not finite.
    peaks : tuple of float
        Strongest spectral peaks [Hz], strongest first.
    missing : float
        Fraction of samples that are NaN [-].
    """

    peak_to_peak: float
    rms: float
    rms_per_axis: tuple[float, ...]
    heart_rate: tuple[float, float]
    peaks: tuple[float, ...]
    missing: float

    def as_dict(self) -> dict:
        """JSON-friendly dict in millimetres, Hz and beats/min."""
        return {
            "peak_to_peak_mm": round(self.peak_to_peak * 1e3, 4),
            "rms_mm": round(self.rms * 1e3, 4),
            "rms_per_axis_mm": [round(v * 1e3, 4) for v in self.rms_per_axis],
            "heart_rate_bpm": [round(v * 60, 2) if np.isfinite(v) else None
                               for v in self.heart_rate],
            "spectral_peaks_hz": [round(v, 3) for v in self.peaks],
            "missing_fraction": round(self.missing, 5),
        }


def motion_stats(source: MotionSource, duration: float, rate: float,
                 t0: float = 0.0) -> MotionStats:
    """Statistics of ``source`` sampled at ``rate`` [Hz] over ``[t0, t0 + duration]``."""
    n = round(duration * rate) + 1
    t = t0 + np.arange(n) / rate
    p = np.asarray(source.position(t)).reshape(n, -1)
    missing = float(np.mean(~np.isfinite(p)))
    finite = p[np.all(np.isfinite(p), axis=1)]
    if finite.shape[0] < 2:
        raise ValueError("the record has fewer than two complete samples")
    filled = fill_gaps(t, p)
    f, s = psd(filled, rate)
    peaks = spectral_peaks(f, s)
    phase = getattr(source, "phase", None)
    if phase is not None and hasattr(phase, "rate"):
        hr = np.asarray(phase.rate(t))
        heart_rate = (float(hr.min()), float(hr.max()))
    else:
        enough = finite.shape[0] / rate >= MIN_BEATS / HEART_BAND[0]
        f_h = spectral_heart_rate(f, s) if enough else float("nan")
        heart_rate = (f_h, f_h)
    per_axis = tuple(float(v) for v in np.sqrt(np.var(finite, axis=0)))
    return MotionStats(peak_to_peak(finite), rms_about_mean(finite), per_axis, heart_rate,
                       tuple(float(v) for v in peaks), missing)


#: Predictability statistic: sample rate [Hz], steps ahead (3 × 40 ms = 120 ms) and warm-up
#: samples (12 s) of :func:`predictability`.
PREDICTABILITY_RATE = 25.0
PREDICTABILITY_AHEAD = 3
PREDICTABILITY_WARMUP = 300


def predictability(source: MotionSource, duration: float, t0: float = 0.0,
                   rate: float = PREDICTABILITY_RATE, ahead: int = PREDICTABILITY_AHEAD,
                   warmup: int = PREDICTABILITY_WARMUP) -> float:
    """How hard the motion is to predict: RMS error of the one-step RLS over that of hold.

    The motion is sampled at ``rate`` (25 Hz) over [t0, t0 + duration]; both predictors
    (Tuna et al. 2013 one-step RLS with its defaults, and hold ẑ_{n+k} = z_n) are fed every
    sample and forecast ``ahead`` samples (3 → 120 ms); the errors
    e_n = ‖ẑ_{n+ahead|n} − z_{n+ahead}‖ after the first ``warmup`` samples (12 s; a third of
    the record when it is shorter than two warm-ups) give

        R = √(mean e²_one-step) / √(mean e²_hold).

    ≈ 0 for a line spectrum (a linear recursion fits it exactly), ≈ 0.12 on a mechanical
    phantom and ≈ 0.69 on in-vivo 3-D heart motion tracked at 25 frames/s. Samples that
    are NaN are fed as missing and not scored. Returns NaN when nothing can be scored.
    """
    from rhmpc.predictors import make_predictor

    n = round(duration * rate) + 1
    z = np.asarray(source.position(t0 + np.arange(n) / rate), dtype=float).reshape(n, -1)
    start = warmup if n >= 2 * warmup else n // 3
    ok = np.all(np.isfinite(z), axis=1)
    rms = {}
    for name in ("hold", "one-step"):
        p = make_predictor(name, dt=1.0 / rate)
        sq = []
        for k in range(n - ahead):
            p.update(z[k] if ok[k] else None)
            if k >= start and ok[k + ahead] and p.ready:
                e = np.asarray(p.predict(ahead))[ahead - 1] - z[k + ahead]
                if np.all(np.isfinite(e)):
                    sq.append(float(e @ e))
        if not sq:
            return float("nan")
        rms[name] = np.sqrt(np.mean(sq))
    return float(rms["one-step"] / rms["hold"]) if rms["hold"] > 0 else float("nan")
