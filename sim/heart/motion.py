r"""Synthetic quasi-periodic heart motion: breathing plus a beat morphology driven by a heart phase.

The point of interest moves as

.. math::

    p(t) = p_0 + b(t) + \bigl(1 + \kappa \cos(2\pi f_r t + \psi_\kappa)\bigr)\,
           g(\varphi(t)) \odot h(\varphi(t)),

with

* :math:`b(t) = \operatorname{Re} \sum_{j=1}^{J} \beta_j e^{i 2\pi j f_r t}`, the breathing
  (ventilator: constant rate :math:`f_r`),
* :math:`h(\varphi) = \operatorname{Re} \sum_{k=1}^{K} c_k e^{i 2\pi k \varphi}`, the beat
  morphology as a band-limited Fourier series in the heart phase φ [cycles] (see
  :mod:`rhmpc.sim.heart.rr`),
* g(φ), a per-axis gain that varies from beat to beat (seeded, interpolated linearly in φ),
* κ, the breathing–heartbeat amplitude coupling.

The physiological variability of :mod:`rhmpc.sim.heart.variability` enters through optional terms: a
breathing phase φ_r(t) of varying period replacing f_r·t, per-breath depths d(φ_r) scaling b,
per-beat timing offsets δ(φ) (h is evaluated at φ + δ), and a slow drift added to p.

All vectors are in metres. Every term is evaluated vectorised, so a whole run (10⁵ samples)
takes a few tens of milliseconds.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from scipy.interpolate import PPoly

from rhmpc.sim.heart.rr import PhaseTrack


@runtime_checkable
class MotionSource(Protocol):
    """Anything that gives the point-of-interest position at any time.

    ``position(t)`` returns metres: shape ``(dim,)`` for a float ``t`` and ``(n, dim)`` for an
    array of shape ``(n,)``. NaN marks times without data (recordings with dropouts).
    """

    dim: int

    def position(self, t: float | np.ndarray) -> np.ndarray: ...


def as_time_array(t: float | np.ndarray) -> tuple[np.ndarray, bool]:
    """``(t as a 1-D float array, whether t was a scalar)``."""
    arr = np.asarray(t, dtype=float)
    if arr.ndim == 0:
        return arr.reshape(1), True
    if arr.ndim != 1:
        raise ValueError(f"t must be a float or a 1-D array, got shape {arr.shape}")
    return arr, False


def _wrapped_bump(phi: np.ndarray, centre: float, width: float) -> np.ndarray:
    """Periodic Gaussian bump exp(−d²/2w²), d the phase distance to ``centre`` wrapped to ±½."""
    d = (phi - centre + 0.5) % 1.0 - 0.5
    return np.exp(-0.5 * (d / width) ** 2)


def fourier_from_bumps(bumps: tuple[tuple[float, float, float], ...], harmonics: int) -> np.ndarray:
    """Complex Fourier coefficients c_1..c_K of one beat built from periodic Gaussian bumps.

    The template is y(φ) = Σ a·bump(φ; centre, width) over ``bumps`` = ((a, centre, width), …);
    its mean is dropped and it is band-limited to ``harmonics`` so that
    y(φ) ≈ Re Σ_k c_k e^{i2πkφ}.
    """
    n = 4096
    phi = np.arange(n) / n
    y = np.zeros(n)
    for a, centre, width in bumps:
        y += a * _wrapped_bump(phi, centre, width)
    spec = np.fft.rfft(y) / n
    return 2.0 * spec[1 : harmonics + 1]


#: Beat templates of the epicardial point of interest, per axis (x, y, z): (amplitude, centre
#: [cycles], width [cycles]) bumps. Phase 0 is the R wave: the wall moves fast during
#: ejection (φ ≈ 0.1–0.35), returns during rapid filling (φ ≈ 0.4–0.55), drifts during diastasis
#: and gets a small atrial kick (φ ≈ 0.85). The narrow bumps give content up to ~25 Hz.
EPICARDIAL_BUMPS: tuple[tuple[tuple[float, float, float], ...], ...] = (
    ((0.55, 0.20, 0.075), (0.25, 0.34, 0.05), (-0.12, 0.50, 0.04), (0.10, 0.86, 0.035),
     (0.06, 0.06, 0.018)),
    ((-0.35, 0.26, 0.12), (0.12, 0.50, 0.07), (-0.06, 0.88, 0.04), (0.04, 0.10, 0.02)),
    ((-1.00, 0.22, 0.085), (-0.45, 0.36, 0.05), (0.18, 0.52, 0.035), (-0.16, 0.87, 0.03),
     (0.10, 0.05, 0.015), (-0.05, 0.42, 0.012)),
)

#: One-axis mitral-annulus template (Yuen et al. 2009 §2), fitted so that at 76 beats/min and
#: 20 mm travel the peak speed is ≈ 210 mm/s and the peak acceleration ≈ 3.8 m/s², with the
#: largest components at harmonics 1, 2 and 4 (1.3, 2.6 and 5.2 Hz).
MITRAL_BUMPS: tuple[tuple[float, float, float], ...] = (
    (1.0, 0.25, 0.133), (0.431, 0.08, 0.064), (0.492, 0.62, 0.079), (0.321, 0.86, 0.131),
)


class SyntheticHeartMotion:
    """Quasi-periodic point-of-interest motion p(t) [m] (see the module docstring).

    Parameters
    ----------
    phase : PhaseTrack
        Heart phase φ(t) [cycles].
    heart : ndarray, shape (dim, K), complex
        Beat Fourier coefficients [m].
    breathing : ndarray, shape (dim, J), complex
        Breathing Fourier coefficients [m].
    breathing_rate : float
        f_r [Hz].
    coupling : float
        κ [-].
    beat_gains : ndarray, shape (n_beats, dim)
        Gain g of beats ``first_beat`` … ``first_beat + n_beats − 1``; beats outside hold the
        nearest value.
    first_beat : int
        Beat number of ``beat_gains[0]``.
    offset : ndarray, shape (dim,)
        p₀ [m].
    coupling_phase : float
        ψ_κ [rad].
    breath_phase : PhaseTrack, optional
        Breathing phase φ_r(t) [cycles] of a breathing with varying period; the breathing and
        the coupling then use φ_r(t) instead of f_r·t (:mod:`rhmpc.sim.heart.variability`).
    breath_depths : ndarray, shape (n_breaths,), optional
        Depth d_j of breaths ``first_breath`` …: b(t) is multiplied by d(φ_r), interpolated
        like the beat gains (needs ``breath_phase``).
    first_breath : int
        Breath number of ``breath_depths[0]``.
    beat_offsets : ndarray, shape (n_beats,), optional
        Per-beat timing offset δ_i of the wall motion [cycles], indexed like ``beat_gains``:
        the morphology is evaluated at φ + δ(φ).
    drift : scipy.interpolate.PPoly, optional
        Slow baseline drift [m], t → (dim,).
    """

    def __init__(self, phase: PhaseTrack, heart: np.ndarray, breathing: np.ndarray,
                 breathing_rate: float, coupling: float = 0.0,
                 beat_gains: np.ndarray | None = None, first_beat: int = 0,
                 offset: np.ndarray | None = None, coupling_phase: float = 0.0, *,
                 breath_phase: PhaseTrack | None = None,
                 breath_depths: np.ndarray | None = None, first_breath: int = 0,
                 beat_offsets: np.ndarray | None = None, drift: PPoly | None = None) -> None:
        self.phase = phase
        self.heart = np.atleast_2d(np.asarray(heart, dtype=complex))
        self.dim = self.heart.shape[0]
        self.breathing = np.atleast_2d(np.asarray(breathing, dtype=complex))
        if self.breathing.shape[0] != self.dim:
            raise ValueError("heart and breathing coefficients need the same number of axes")
        self.breathing_rate = float(breathing_rate)
        self.coupling = float(coupling)
        self.coupling_phase = float(coupling_phase)
        if beat_gains is None:
            beat_gains = np.ones((1, self.dim))
        self.beat_gains = np.asarray(beat_gains, dtype=float).reshape(-1, self.dim)
        self.first_beat = int(first_beat)
        self.offset = np.zeros(self.dim) if offset is None else np.asarray(offset, dtype=float)
        self.breath_phase = breath_phase
        self.breath_depths = None if breath_depths is None else np.asarray(breath_depths, float)
        if self.breath_depths is not None and breath_phase is None:
            raise ValueError("breath_depths need a breath_phase")
        self.first_breath = int(first_breath)
        self.beat_offsets = None if beat_offsets is None else np.asarray(beat_offsets, float)
        self.drift = drift
        self._heart = _Series(self.heart)
        self._breath = _Series(self.breathing)

    def _variations(self) -> dict:
        return dict(breath_phase=self.breath_phase, breath_depths=self.breath_depths,
                    first_breath=self.first_breath, beat_offsets=self.beat_offsets)

    def scaled(self, factor: float | np.ndarray) -> SyntheticHeartMotion:
        """The same motion with its displacement about p₀ multiplied by ``factor`` (per axis)."""
        f = np.broadcast_to(np.asarray(factor, dtype=float), (self.dim,))[:, None]
        drift = None
        if self.drift is not None:
            drift = PPoly(self.drift.c * f[:, 0], self.drift.x, extrapolate=True)
        return SyntheticHeartMotion(self.phase, self.heart * f, self.breathing * f,
                                    self.breathing_rate, self.coupling, self.beat_gains,
                                    self.first_beat, self.offset, self.coupling_phase,
                                    drift=drift, **self._variations())

    def heartbeat(self, t: float | np.ndarray) -> np.ndarray:
        """The cardiac part (1 + κ cos(2π f_r t + ψ_κ))·g(φ)⊙h(φ(t)) [m], shape like position."""
        ts, scalar = as_time_array(t)
        out = self._heartbeat(ts)
        return out[0] if scalar else out

    def breathing_motion(self, t: float | np.ndarray) -> np.ndarray:
        """The breathing part b(t) [m], shape like position."""
        ts, scalar = as_time_array(t)
        out = self._breathing(ts)
        return out[0] if scalar else out

    def _breath_cycles(self, ts: np.ndarray) -> np.ndarray:
        if self.breath_phase is None:
            return self.breathing_rate * ts
        return self.breath_phase(ts)

    def _breathing(self, ts: np.ndarray) -> np.ndarray:
        cycles = self._breath_cycles(ts)
        out = self._breath(cycles)
        if self.breath_depths is not None:
            out *= per_cycle(self.breath_depths, self.first_breath, cycles)
        return out

    def _heartbeat(self, ts: np.ndarray) -> np.ndarray:
        phi = self.phase(ts)
        if self.beat_offsets is not None:
            phi = phi + per_cycle(self.beat_offsets, self.first_beat, phi)[:, 0]
        h = self._heart(phi)
        if self.beat_gains.shape[0] > 1:
            g = per_cycle(self.beat_gains, self.first_beat, phi)
        else:
            g = self.beat_gains[0]
        if self.breath_phase is None:
            arg = 2 * np.pi * self.breathing_rate * ts
        else:
            arg = 2 * np.pi * self.breath_phase(ts)
        mod = 1.0 + self.coupling * np.cos(arg + self.coupling_phase)
        return mod[:, None] * g * h

    def position(self, t: float | np.ndarray) -> np.ndarray:
        """p(t) [m]: shape (dim,) for a float, (n, dim) for an array of n times."""
        ts, scalar = as_time_array(t)
        out = self.offset + self._breathing(ts) + self._heartbeat(ts)
        if self.drift is not None:
            out += self.drift(ts)
        return out[0] if scalar else out


def per_cycle(values: np.ndarray, first: int, cycles: np.ndarray) -> np.ndarray:
    """Per-cycle values v_i at cycle position ``cycles``: shape (n, k).

    Cycle i's value applies at mid-cycle i + ½, linear in the cycle count in between and held
    beyond the first and last cycles (``values`` (n_cycles,) or (n_cycles, k), cycle numbers
    ``first`` … ``first + n_cycles − 1``).
    """
    v = np.asarray(values, dtype=float).reshape(len(values), -1)
    n = v.shape[0]
    if n == 1:
        return np.broadcast_to(v[0], (cycles.shape[0], v.shape[1]))
    u = np.clip(cycles - first - 0.5, 0.0, n - 1.0)
    i = np.minimum(u.astype(np.int64), n - 2)
    w = (u - i)[:, None]
    return (1.0 - w) * v[i] + w * v[i + 1]


class _Series:
    """Re Σ_k c_{d,k} e^{i2πk·cycles} with the coefficients prepared once."""

    def __init__(self, coef: np.ndarray) -> None:
        self.coef = coef
        self.re = np.ascontiguousarray(coef.real)
        self.im = np.ascontiguousarray(coef.imag)
        self.re_t = np.ascontiguousarray(coef.real.T)
        self.im_t = np.ascontiguousarray(coef.imag.T)
        self.k = np.arange(1, coef.shape[1] + 1, dtype=float)

    def __call__(self, cycles: np.ndarray) -> np.ndarray:
        if cycles.shape[0] < 2048 or self.k.size < 4:
            arg = np.outer(2 * np.pi * np.mod(cycles, 1.0), self.k)
            return np.cos(arg) @ self.re_t - np.sin(arg) @ self.im_t
        return _fourier(self.coef, cycles)


def _fourier(coef: np.ndarray, cycles: np.ndarray) -> np.ndarray:
    """Re Σ_k c_{d,k} e^{i2πk·cycles} for every axis d: shape (n, dim).

    For long inputs cos(kx) and sin(kx) come from the angle-addition recurrence, so only one
    cos/sin pair is evaluated per sample.
    """
    n, harmonics = cycles.shape[0], coef.shape[1]
    x = 2 * np.pi * np.mod(cycles, 1.0)
    if n < 2048:  # few samples (one control tick): one vectorised cos/sin beats the loop
        arg = np.outer(x, np.arange(1, harmonics + 1))
        return np.cos(arg) @ coef.real.T - np.sin(arg) @ coef.imag.T
    c1, s1 = np.cos(x), np.sin(x)
    cos_k = np.empty((harmonics, n))
    sin_k = np.empty((harmonics, n))
    cos_k[0], sin_k[0] = c1, s1
    for k in range(1, harmonics):
        np.subtract(cos_k[k - 1] * c1, sin_k[k - 1] * s1, out=cos_k[k])
        np.add(sin_k[k - 1] * c1, cos_k[k - 1] * s1, out=sin_k[k])
    re = np.ascontiguousarray(coef.real)
    im = np.ascontiguousarray(coef.imag)
    return (re @ cos_k - im @ sin_k).T

