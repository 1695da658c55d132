"""Batch initialisation of Fourier-series predictors (Yuen et al. 2008, §III-A).

1. Fundamental: the largest peak of the Hamming-windowed power spectrum inside the
   heart-rate band (0.5–2.5 Hz), summed over axes (one shared ω).  The FFT is
   zero-padded and the peak refined by a parabola through the log-power of its
   neighbours, so ω̂₀ is not quantised to the 1/T bin width.
2. Harmonics: with ω̂₀ fixed, eq. (3) y(t) = c₀ + Σ_i a_i sin(iω̂₀t) + b_i cos(iω̂₀t)
   is linear; least squares gives c₀, a_i, b_i per axis.  Time is measured from
   the newest sample (t = 0 there), so r_i = √(a_i² + b_i²) and
   θ_i = atan2(b_i, a_i) are directly the state at the end of the window.
   Harmonics at or above 0.45·f_s (aliased) are left out (amplitude 0).
3. Breathing (:func:`initial_dual_state`): the respiratory fundamental ω_b is the FFT
   peak in the breathing band; its harmonics are fitted by least squares and removed
   before the heart rate is searched in the heart band, so that breathing harmonics
   cannot capture ω̂₀; then heart and breathing series are fitted jointly (eq. 3 with
   both sums, as Richa et al. 2010 eq. 1).

The Fourier EKFs keep the last window of samples (:class:`FitWindow`) after the fit and fit
it again when their rate estimate leaves the band the FFT searched (``lock_refit``);
:func:`wrap_phase` and :func:`spd_inverse` are their shared numerics.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotri

__all__ = [
    "FitWindow",
    "fit_fourier",
    "fit_harmonics",
    "fundamental_frequency",
    "initial_dual_state",
    "initial_fourier_state",
    "spd_inverse",
    "wrap_phase",
]

_TWO_PI = 2.0 * math.pi


class FitWindow:
    """The last ``n`` samples (d,) of a stream, NaN for a missing one, for the batch fit.

    The fit uses the window once it is full and at least 80 % of its rows are finite.
    """

    def __init__(self, n: int, d: int) -> None:
        self.samples = np.full((n, d), np.nan)  # circular; row ``count % n`` is the oldest
        self.count = 0  # samples pushed since the last clear

    def push(self, z: np.ndarray | float) -> None:
        """Append a sample (NaN: missing), overwriting the oldest."""
        self.samples[self.count % self.samples.shape[0]] = z
        self.count += 1

    def clear(self) -> None:
        self.samples[:], self.count = np.nan, 0

    @property
    def full(self) -> bool:
        return self.count >= self.samples.shape[0]

    def usable(self) -> bool:
        """Full, and ≥ 80 % of the rows finite."""
        return self.full and np.isfinite(self.samples).all(axis=1).mean() >= 0.8

    def newest(self, k: int) -> np.ndarray:
        """The newest ``k`` ≤ n samples, newest first (k, d)."""
        n = self.samples.shape[0]
        return self.samples[(self.count - 1 - np.arange(k)) % n]

    def oldest_first(self) -> np.ndarray:
        """A copy of the window in time order (n, d)."""
        n = self.samples.shape[0]
        return self.samples[np.roll(np.arange(n), -(self.count % n))]


def wrap_phase(theta: np.ndarray) -> np.ndarray:
    """Wrap angles to (−π, π] in place and return them."""
    np.subtract(theta, _TWO_PI * np.floor((theta + math.pi) / _TWO_PI), out=theta)
    return theta


def spd_inverse(S: np.ndarray) -> np.ndarray | None:
    """S⁻¹ of a small symmetric positive definite matrix, or ``None`` if S is not SPD.

    Closed forms for 1×1 and 3×3 (Sylvester's criterion for definiteness), LAPACK
    ``potrf``/``potri`` otherwise: ``np.linalg.inv`` costs ~50 µs of overhead per call.
    """
    d = S.shape[0]
    if d == 1:
        s = float(S[0, 0])
        return np.array([[1.0 / s]]) if s > 0.0 and math.isfinite(s) else None
    if d == 3:
        a, b, c, _, e, f, _, _, i = S.ravel().tolist()  # symmetric: use the upper triangle
        A, B, C = e * i - f * f, c * f - b * i, b * f - c * e
        det = a * A + b * B + c * C
        if not (a > 0.0 and a * e - b * b > 0.0 and det > 0.0 and math.isfinite(det)):
            return None
        return (
            np.array(
                [[A, B, C], [B, a * i - c * c, b * c - a * f], [C, b * c - a * f, a * e - b * b]]
            )
            / det
        )
    c, info = dpotrf(S, lower=0, clean=1)
    if info != 0:
        return None
    inv, info = dpotri(c, lower=0)
    if info != 0 or not np.isfinite(inv).all():
        return None
    return np.triu(inv) + np.triu(inv, 1).T


def fundamental_frequency(
    window: np.ndarray, dt: float, band_hz: tuple[float, float] = (0.5, 2.5), pad: int = 8
) -> float:
    """ω̂₀ [rad/s] of ``window`` (T, d) sampled at ``dt`` [s]; NaN rows are ignored."""
    x = np.array(window, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    mean = np.nanmean(x, axis=0)
    x = np.where(np.isfinite(x), x - mean, 0.0)
    T = x.shape[0]
    # zero-padded to at least 4 bins across the band, so a short window still has a peak
    width = band_hz[1] - band_hz[0]
    nfft = int(2 ** np.ceil(np.log2(max(T * pad, 4.0 / (dt * width)))))
    spec = np.abs(np.fft.rfft(x * np.hamming(T)[:, None], n=nfft, axis=0)) ** 2
    power = spec.sum(axis=1)
    f = np.fft.rfftfreq(nfft, dt)
    band = np.flatnonzero((f >= band_hz[0]) & (f <= band_hz[1]))
    if band.size == 0:
        raise ValueError(f"no FFT bin in {band_hz} Hz (window {T * dt:.2f} s at dt={dt})")
    k = band[np.argmax(power[band])]
    fk = f[k]
    if 0 < k < power.size - 1 and np.all(power[k - 1 : k + 2] > 0):
        la, lb, lc = np.log(power[k - 1 : k + 2])
        den = la - 2 * lb + lc
        if den < 0:  # the vertex, within half a bin (at a band edge the peak may lie outside)
            fk += min(max(0.5 * (la - lc) / den, -0.5), 0.5) * (f[1] - f[0])
    return 2 * np.pi * float(min(max(fk, band_hz[0]), band_hz[1]))


def fit_fourier(
    window: np.ndarray, dt: float, series: list[tuple[float, int]], ridge: float = 1e-9
) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """Least squares c₀ (d,) and, per (ω, m) in ``series``, a (d, m), b (d, m), t = 0 at the end.

    y(t) = c₀ + Σ_series Σ_i a_i sin(iωt) + b_i cos(iωt) on ``window`` (T, d).  A tiny
    ridge (``ridge`` × mean diagonal of AᵀA) keeps the normal equations regular; rows
    with NaN are dropped; aliased harmonics (≥ 0.45 f_s) get a = b = 0.
    """
    x = np.array(window, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    T, d = x.shape
    t = (np.arange(T) - (T - 1)) * dt
    keep = np.isfinite(x).all(axis=1)
    cols, usable = [np.ones((int(keep.sum()), 1))], []
    for omega, m in series:
        ok = np.arange(1, m + 1) * omega / (2 * np.pi) < 0.45 / dt
        ph = np.outer(t[keep], np.arange(1, m + 1)[ok] * omega)
        cols += [np.sin(ph), np.cos(ph)]
        usable.append(ok)
    A = np.hstack(cols)
    G = A.T @ A
    G[np.diag_indices_from(G)] += ridge * np.trace(G) / G.shape[0]
    coef = np.linalg.solve(G, A.T @ x[keep])  # (1 + 2Σk, d)
    out, j = [], 1
    for (_, m), ok in zip(series, usable, strict=True):
        k = int(ok.sum())
        a, b = np.zeros((d, m)), np.zeros((d, m))
        a[:, ok], b[:, ok] = coef[j : j + k].T, coef[j + k : j + 2 * k].T
        out.append((a, b))
        j += 2 * k
    return coef[0].copy(), out


def fit_harmonics(
    window: np.ndarray, dt: float, omega: float, m: int, ridge: float = 1e-9
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """c₀ (d,), a (d, m), b (d, m) of eq. (3) alone (one series), t = 0 at the end."""
    c, [(a, b)] = fit_fourier(window, dt, [(omega, m)], ridge)
    return c, a, b


def initial_fourier_state(
    window: np.ndarray, dt: float, m: int, band_hz: tuple[float, float] = (0.5, 2.5)
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """(ω̂₀ [rad/s], c (d,), r (d, m), θ (d, m)) at the newest sample of ``window``."""
    omega = fundamental_frequency(window, dt, band_hz)
    c, a, b = fit_harmonics(window, dt, omega, m)
    return omega, c, np.hypot(a, b), np.arctan2(b, a)


def initial_dual_state(
    window: np.ndarray,
    dt: float,
    m: int,
    band_hz: tuple[float, float],
    breathing_harmonics: int,
    breathing_band_hz: tuple[float, float],
    breathing_omega: float | None = None,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
    """(ω̂₀, c, r, θ, ω̂_b, a_b, b_b) at the newest sample: heart series as in
    :func:`initial_fourier_state`, breathing series y_b = Σ_h a_h sin hθ_b + b_h cos hθ_b
    with θ_b = 0 at the newest sample.  ω̂₀ is searched after the breathing fit is removed.
    ``breathing_omega`` [rad/s]: a known respiratory rate (a ventilator's setting) used
    instead of the FFT peak, which a window of 1–2 breaths resolves only to ±0.05 Hz.
    """
    x = np.array(window, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    T = x.shape[0]
    t = (np.arange(T) - (T - 1)) * dt
    if breathing_omega is None:
        omega_b = fundamental_frequency(x, dt, breathing_band_hz)
    else:
        omega_b = float(breathing_omega)
    c, [(a, b)] = fit_fourier(x, dt, [(omega_b, breathing_harmonics)])
    ph = np.multiply.outer(t, np.arange(1, breathing_harmonics + 1) * omega_b)
    heart_only = x - c - np.sin(ph) @ a.T - np.cos(ph) @ b.T
    omega = fundamental_frequency(heart_only, dt, band_hz)
    c, [(ah, bh), (a, b)] = fit_fourier(x, dt, [(omega, m), (omega_b, breathing_harmonics)])
    return omega, c, np.hypot(ah, bh), np.arctan2(bh, ah), omega_b, a, b


def fit_covariance(n: int, dt: float, series: list[tuple[float, int]]) -> np.ndarray:
    """(AᵀA)⁻¹ of the design of :func:`fit_fourier` for ``n`` samples (t = 0 at the newest):
    columns [1, sin iω₁t (i ≤ m₁), cos iω₁t, sin iω₂t, …]; × a residual variance it is the
    least-squares covariance of [c₀, a, b, …]."""
    t = (np.arange(n) - (n - 1)) * dt
    cols = [np.ones((n, 1))]
    for omega, m in series:
        ph = np.outer(t, np.arange(1, m + 1) * omega)
        cols += [np.sin(ph), np.cos(ph)]
    A = np.hstack(cols)
    return np.linalg.pinv(A.T @ A)
