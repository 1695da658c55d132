"""In-vivo regime: breathing-dominated epicardial motion with large beat-to-beat variation.

A synthetic regime built from the statistics of a real 3-D in-vivo recording of points on a
beating heart, tracked from stereo endoscopic video at 25 frames/s (:data:`RECORDING`; the
recording itself is not part of the project). Nothing here is measured data.

Model, per axis (all terms in metres):

    p(t) = d(φ_r)·b(φ_r(t)) + (1 + κ cos(2π φ_r + ψ_κ))·g(φ)⊙h(ψ(t)) + drift(t),

with

* φ(t): the heart phase through the beat times t_i (φ(t_i) = i). The RR intervals are the
  LF/HF tachogram of McSharry et al. (2003), IEEE Trans. Biomed. Eng. 50:289
  (:func:`rhmpc.sim.heart.rr.synthetic_rr`): Gaussian spectral bumps at 0.1 Hz (Mayer waves) and at
  the breathing rate (respiratory sinus arrhythmia), mean and SD those of the recording
  (1.2 s = 50 beats/min, 0.14 s, the middle of its 0.10–0.18 s), clipped to its 0.72–1.56 s.
* ψ(t): the mechanical phase at which the beat template h is read. The template
  (:data:`rhmpc.sim.heart.motion.EPICARDIAL_BUMPS`, the replicas' beat at ``REFERENCE_RR`` = 0.6 s)
  is split at its end of systole ψ_S, end of rapid filling ψ_E and onset of atrial contraction
  ψ_A. In beat i of length RR_i:

  - systole [0, ψ_S] lasts S_i = ψ_S·RR_ref·QS2(HR_i)/QS2(HR_ref), with the electromechanical
    systole QS2 = 546 − 2.1·HR ms (HR in beats/min; Weissler, Harris & Schoenfeld 1968,
    Circulation 37:149): systole barely shortens with rate;
  - rapid filling [ψ_S, ψ_E] and atrial systole [ψ_A, 1] keep their durations at the
    reference, (ψ_E − ψ_S)·RR_ref and (1 − ψ_A)·RR_ref;
  - diastasis [ψ_E, ψ_A] takes the rest: it is the phase of diastole that absorbs changes of
    the RR interval (Chung, Karamanoglu & Kovács 2004, Am. J. Physiol. Heart 287:H2003).

  ψ is the monotone cubic (PCHIP) through these knots. A long beat is therefore not a slowed
  copy of a short one: its contraction is as fast and its quiet diastasis longer — the shape
  of the beat changes with every RR interval, which a Fourier series in one phase cannot
  follow.
* g_i: per-beat, per-axis stroke gains 1 + s_i, s an AR(1) series
  (:func:`rhmpc.sim.heart.variability.ar1`) with lag-one correlation 0.3 (as
  :mod:`rhmpc.sim.heart.variability`) and SD ``beat_gain_std``.
* b, d, φ_r: breathing at 0.165 Hz (the recording's), fundamental plus a second harmonic of
  0.35 (as the replicas), through breath onsets of varying period and depth
  (:func:`rhmpc.sim.heart.variability.breathing_phase`); κ = 0.08 and the drift as
  :class:`rhmpc.sim.heart.variability.VariabilitySettings`.

Calibration (:func:`invivo_motion`): the beat template is scaled to ``heart_rms`` (3-D RMS of
one unvaried beat), then each axis's breathing amplitude is solved so that the axis's
peak-to-peak over the nominal record is the recording's (5.1 / 2.3 / 4.4 mm).

Three magnitudes have no physiological source at this size and are set from the recording's
statistics instead (:data:`RECORDING`): ``heart_rms`` and ``beat_gain_std`` so that the best
fixed-frequency Fourier fit leaves a periodic cardiac part of 0.41–0.50 mm and a residual of
0.84–0.96 mm; the breathing period and depth CVs, in the ratio of Tobin et al. (1988), J. Appl.
Physiol. 65:309 (0.21 : 0.33, spontaneous breathing), at 0.45 of theirs, so that ≈ 69 % of the
residual's power lies in 0.5–3 Hz. :func:`regime_statistics` measures all of them; the
forecast errors of ``hold`` then follow without being tuned (``rhmpc data show invivo-video``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator, PPoly

from rhmpc.sim.heart.motion import EPICARDIAL_BUMPS, SyntheticHeartMotion, fourier_from_bumps
from rhmpc.sim.heart.rr import PhaseTrack, RRSettings, beat_times_from_rr, synthetic_rr
from rhmpc.sim.heart.variability import (
    VariabilitySettings,
    ar1,
    breathing_phase,
    drift_knots,
    smooth_knots,
)

__all__ = ["RECORDING", "InVivoSettings", "MechanicalPhase", "invivo_motion",
           "regime_statistics"]

#: The in-vivo recording's statistics (3-D point tracked by stereo video at 25 frames/s, four
#: points): per-axis peak-to-peak [mm], breathing and heart rates [Hz], beat intervals [s],
#: the best fixed-frequency Fourier fit (3 breathing + 5 cardiac harmonics, in-sample): its
#: periodic cardiac part and residual [mm RMS, 3-D] and the residual's power fraction in
#: 0.5–3 Hz, and ``hold``'s 3-D forecast RMS at 1/3/5 samples [mm].
RECORDING: dict[str, object] = {
    "peak_to_peak_mm": (5.1, 2.3, 4.4),
    "breathing_hz": 0.165,
    "heart_hz": 0.83,
    "beat_interval_s": (0.72, 1.56),
    "beat_interval_sd_s": (0.10, 0.18),
    "periodic_mm": (0.41, 0.50),
    "residual_mm": (0.84, 0.96),
    "residual_band_fraction": 0.69,
    "hold_mm": (0.57, 1.04, 1.32),
}

#: Template phase [cycles] at the end of systole, of rapid filling, and at the onset of atrial
#: contraction (EPICARDIAL_BUMPS: ejection 0.1–0.35, return during rapid filling 0.4–0.55,
#: atrial kick at 0.85).
PSI_SYSTOLE, PSI_FILLING, PSI_ATRIAL = 0.40, 0.60, 0.80
#: RR interval at which EPICARDIAL_BUMPS is the beat (the replicas' 100 beats/min) [s].
REFERENCE_RR = 0.6


def qs2(heart_rate_bpm: np.ndarray | float) -> np.ndarray | float:
    """Electromechanical systole QS2 = 546 − 2.1·HR [ms] (Weissler et al. 1968, men)."""
    return 546.0 - 2.1 * np.asarray(heart_rate_bpm, dtype=float)


@dataclass(frozen=True)
class InVivoSettings:
    """Magnitudes of the in-vivo regime (module docstring).

    Attributes
    ----------
    heart_rate : float
        Mean heart rate [Hz] (the recording: 0.83).
    rr_std : float
        SD of the RR intervals [s] (the recording: 0.10–0.18).
    rr_range : tuple of float
        RR intervals are clipped to this range [s] (the recording's).
    breathing_rate : float
        Mean breathing rate [Hz] (the recording: 0.165).
    breath_period_cv, breath_depth_cv : float
        Coefficients of variation of breath duration and depth [-].
    heart_rms : float
        3-D RMS of one unvaried beat of the template [m].
    beat_gain_std : float
        SD of the per-beat, per-axis stroke gain [-].
    beat_gain_correlation : float
        Lag-one correlation of the stroke gains [-].
    heart_axes : tuple of float
        Relative weights of the beat template on x, y, z [-].
    peak_to_peak : tuple of float
        Per-axis peak-to-peak the breathing amplitudes are solved for [m].
    """

    heart_rate: float = 0.83
    rr_std: float = 0.14
    rr_range: tuple[float, float] = (0.72, 1.56)
    breathing_rate: float = 0.165
    breath_period_cv: float = 0.45 * 0.21
    breath_depth_cv: float = 0.45 * 0.33
    heart_rms: float = 1.0e-3
    beat_gain_std: float = 0.30
    beat_gain_correlation: float = 0.3
    heart_axes: tuple[float, float, float] = (1.0, 0.7, 0.7)
    peak_to_peak: tuple[float, float, float] = (5.1e-3, 2.3e-3, 4.4e-3)

    def __post_init__(self) -> None:
        for name in ("heart_rate", "rr_std", "breathing_rate", "heart_rms"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        lo, hi = self.rr_range
        if not 0 < lo < 1.0 / self.heart_rate < hi:
            raise ValueError("rr_range must bracket the mean RR interval 1/heart_rate")
        for name in ("breath_period_cv", "breath_depth_cv", "beat_gain_std"):
            if not 0 <= getattr(self, name) < 0.5:
                raise ValueError(f"{name} must be in [0, 0.5), got {getattr(self, name)!r}")


class MechanicalPhase(PhaseTrack):
    """The template phase ψ(t) of the systole/filling/diastasis/atrial warp (module docstring).

    ψ(t_i) = i at the beat times like the heart phase, so beat gains index the same beats;
    :meth:`rate` is the heart rate of the beat times (1/RR), not dψ/dt.

    Parameters
    ----------
    beat_times : ndarray, shape (n,)
        Strictly increasing beat onsets t_i [s], n ≥ 2.
    """

    def __init__(self, beat_times: np.ndarray) -> None:
        tb = np.asarray(beat_times, dtype=float)
        rr = np.diff(tb)
        systole = PSI_SYSTOLE * REFERENCE_RR * qs2(60.0 / rr) / qs2(60.0 / REFERENCE_RR)
        filling = (PSI_FILLING - PSI_SYSTOLE) * REFERENCE_RR
        atrial = (1.0 - PSI_ATRIAL) * REFERENCE_RR
        if np.any(systole + filling + atrial >= rr):
            raise ValueError("an RR interval is shorter than systole + rapid filling + atrial "
                             f"systole ({np.min(systole) + filling + atrial:.3f} s)")
        start = tb[:-1]
        knots_t = np.stack([start, start + systole, start + systole + filling,
                            tb[1:] - atrial], axis=1).ravel()
        knots_psi = (np.arange(rr.size)[:, None]
                     + np.array([0.0, PSI_SYSTOLE, PSI_FILLING, PSI_ATRIAL])).ravel()
        p = PchipInterpolator(np.append(knots_t, tb[-1]), np.append(knots_psi, rr.size))
        super().__init__(PPoly(p.c, p.x, extrapolate=True))
        self._beats = PhaseTrack.from_beat_times(tb)

    def rate(self, t: float | np.ndarray) -> np.ndarray:
        """Heart rate [Hz] of the beat times (PCHIP through them), not dψ/dt."""
        return self._beats.rate(t)


def invivo_motion(rng: np.random.Generator, horizon: float, nominal: float,
                  settings: InVivoSettings | None = None) -> SyntheticHeartMotion:
    """Draw the in-vivo regime's motion over [0, ``horizon``] [s], calibrated on [0, ``nominal``].

    Parameters
    ----------
    rng : numpy.random.Generator
        All the draws: RR intervals, breaths, stroke gains, phases, drift.
    horizon : float
        Seconds the draws must cover [s].
    nominal : float
        Record length on which the peak-to-peak is calibrated [s] (sampled at 25 Hz).
    settings : InVivoSettings, optional
        Magnitudes (default: the recording's).
    """
    s = InVivoSettings() if settings is None else settings
    rr = synthetic_rr(horizon + 20.0, rng, RRSettings(
        mean_rate=s.heart_rate, std=s.rr_std, hf=s.breathing_rate, min_rr=s.rr_range[0]))
    beats = beat_times_from_rr(np.clip(rr, *s.rr_range), -10.0)
    phase = MechanicalPhase(beats)
    heart = np.stack([w * fourier_from_bumps(b, 20)
                      for w, b in zip(s.heart_axes, EPICARDIAL_BUMPS, strict=True)])
    heart *= s.heart_rms / np.sqrt(0.5 * np.sum(np.abs(heart) ** 2))  # Parseval
    psi = 2 * np.pi * rng.random()
    unit_breath = np.array([np.exp(1j * psi), 0.35 * np.exp(1j * (2 * psi + 0.6))])
    breath = breathing_phase(rng, s.breathing_rate, horizon, s.breath_period_cv)
    first_breath = int(np.floor(float(breath(-5.0))))
    n_breaths = int(np.ceil(float(breath(horizon + 5.0)))) - first_breath + 1
    depths = 1.0 + s.breath_depth_cv * np.clip(rng.standard_normal(n_breaths), -2.5, 2.5)
    gains = 1.0 + ar1(rng, beats.size + 1, s.beat_gain_std, s.beat_gain_correlation, 3)
    v = VariabilitySettings()
    drift = smooth_knots(*drift_knots(rng, horizon, 3, v.drift_std * s.peak_to_peak[0],
                                      v.drift_cutoff))
    coupling_phase = 2 * np.pi * rng.random()

    def motion(breathing: np.ndarray) -> SyntheticHeartMotion:
        return SyntheticHeartMotion(
            phase, heart, breathing, s.breathing_rate, v.coupling, gains, -1,
            coupling_phase=coupling_phase, breath_phase=breath, breath_depths=depths,
            first_breath=first_breath, drift=drift)

    unit = np.outer(np.ones(3), unit_breath)
    t = np.arange(round(nominal * 25.0) + 1) / 25.0
    amp = breathing_amplitudes(motion(unit), t, np.asarray(s.peak_to_peak))
    return motion(unit * amp[:, None])


def breathing_amplitudes(motion: SyntheticHeartMotion, t: np.ndarray,
                         target: np.ndarray) -> np.ndarray:
    """Per-axis factors a ≥ 0 of the breathing term giving peak-to-peak ``target`` at ``t``.

    The peak-to-peak of the rest + a·breathing grows with a: bisection per axis (40 steps).
    """
    breath = motion.breathing_motion(t)
    rest = motion.position(t) - breath
    amp = np.empty(motion.dim)
    for d in range(motion.dim):
        lo, hi = 0.0, 10.0 * target[d] / max(float(np.ptp(breath[:, d])), 1e-12)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if np.ptp(rest[:, d] + mid * breath[:, d]) < target[d]:
                lo = mid
            else:
                hi = mid
        amp[d] = 0.5 * (lo + hi)
    return amp


def fourier_basis(n: int, rate: float, breathing_hz: float, heart_hz: float,
                  breathing_harmonics: int = 3, heart_harmonics: int = 5) -> np.ndarray:
    """(n, 1 + 2H_b + 2H_c) columns: 1, sin/cos 2πh f_b t (h ≤ H_b), sin/cos 2πh f_h t (h ≤ H_c)."""
    t = np.arange(n) / rate
    cols = [np.ones((n, 1))]
    for f, m in ((breathing_hz, breathing_harmonics), (heart_hz, heart_harmonics)):
        arg = 2 * np.pi * f * np.outer(t, np.arange(1, m + 1))
        cols += [np.sin(arg), np.cos(arg)]
    return np.hstack(cols)


def fourier_fit(z: np.ndarray, rate: float, breathing_hz: float, heart_hz: float,
                breathing_harmonics: int = 3, heart_harmonics: int = 5
                ) -> tuple[np.ndarray, np.ndarray]:
    r"""Least-squares fixed-frequency Fourier fit of ``z`` (n, d): (fit, its cardiac part).

    .. math::

        z(t) \approx c + \sum_{h \le H_b} \bigl(a_h \sin 2\pi h f_b t + b_h \cos 2\pi h f_b t\bigr)
                      + \sum_{h \le H_c} \bigl(d_h \sin 2\pi h f_h t + e_h \cos 2\pi h f_h t\bigr)

    (normal equations with a 1e-9 relative ridge).
    """
    A = fourier_basis(len(z), rate, breathing_hz, heart_hz, breathing_harmonics,
                      heart_harmonics)
    G = A.T @ A
    G[np.diag_indices_from(G)] += 1e-9 * np.trace(G) / G.shape[0]
    coef = np.linalg.solve(G, A.T @ z)
    k = 1 + 2 * breathing_harmonics
    return A @ coef, A[:, k:] @ coef[k:]


def best_fourier_frequencies(z: np.ndarray, rate: float) -> tuple[float, float]:
    """(f_b, f_h) [Hz] of the fixed-frequency fit with the least residual.

    Grid over 0.08–0.40 Hz (0.01 Hz) × 0.5–2.0 Hz (0.025 Hz, a third of the 1/60 s resolution
    of a minute), refined by Nelder–Mead from the best node.
    """
    from scipy.optimize import minimize

    def cost(f: np.ndarray) -> float:
        fit, _ = fourier_fit(z, rate, float(f[0]), float(f[1]))
        return float(np.sum((z - fit) ** 2))

    grid = [(cost(np.array([fb, fh])), fb, fh) for fb in np.arange(0.08, 0.40, 0.01)
            for fh in np.arange(0.5, 2.0, 0.025)]
    best = minimize(cost, np.array(min(grid)[1:]), method="Nelder-Mead",
                    options={"xatol": 1e-5, "fatol": 1e-14})
    return float(best.x[0]), float(best.x[1])


def regime_statistics(z: np.ndarray, rate: float, beat_times: np.ndarray | None = None,
                      warmup: int = 300) -> dict[str, object]:
    """The statistics of :data:`RECORDING` measured on samples ``z`` (n, 3) [m] at ``rate``.

    ``beat_times`` [s] (optional) give the beat-interval range and SD. Hold errors are scored
    from sample ``warmup`` on, as the predictor checks do.
    """
    z = np.asarray(z, dtype=float)
    out: dict[str, object] = {}
    if beat_times is not None and len(beat_times) > 2:
        rr = np.diff(np.asarray(beat_times, dtype=float))
        out["beat_interval_s"] = (round(float(rr.min()), 3), round(float(rr.max()), 3))
        out["beat_interval_sd_s"] = round(float(rr.std()), 3)
    fb, fh = best_fourier_frequencies(z, rate)
    fit, cardiac = fourier_fit(z, rate, fb, fh)
    res = z - fit
    power = np.sum(np.abs(np.fft.rfft(res, axis=0)) ** 2, axis=1)
    f = np.fft.rfftfreq(len(res), 1.0 / rate)
    band = (f >= 0.5) & (f <= 3.0)
    hold = [float(np.sqrt(np.mean(np.sum((z[warmup + k:] - z[warmup:-k]) ** 2, axis=1))))
            for k in (1, 3, 5)]
    return out | {
        "peak_to_peak_mm": tuple(round(float(v) * 1e3, 3) for v in np.ptp(z, axis=0)),
        "breathing_hz": round(fb, 4),
        "heart_hz": round(fh, 4),
        "periodic_mm": round(1e3 * float(np.sqrt(np.mean(np.sum(
            (cardiac - cardiac.mean(axis=0)) ** 2, axis=1)))), 3),
        "residual_mm": round(1e3 * float(np.sqrt(np.mean(np.sum(res**2, axis=1)))), 3),
        "residual_band_fraction": round(float(power[band].sum() / power[1:].sum()), 3),
        "hold_mm": tuple(round(1e3 * v, 3) for v in hold),
    }


def source_statistics(source: SyntheticHeartMotion, duration: float,
                      rate: float = 25.0) -> dict[str, object]:
    """:func:`regime_statistics` of ``source`` sampled at ``rate`` over [0, ``duration``]."""
    t = np.arange(round(duration * rate) + 1) / rate
    beats = source.phase.beat_times(0.0, duration) if hasattr(source.phase, "beat_times") else None
    return regime_statistics(source.position(t), rate, beats)


def statistics_table(measured: dict[str, object]) -> list[str]:
    """Lines ``statistic   this source   the recording`` for the keys of :data:`RECORDING`."""
    labels = {
        "peak_to_peak_mm": "peak-to-peak [mm]", "breathing_hz": "breathing [Hz]",
        "heart_hz": "heart [Hz]", "beat_interval_s": "beat intervals [s]",
        "beat_interval_sd_s": "beat-interval SD [s]", "periodic_mm": "periodic cardiac [mm]",
        "residual_mm": "fit residual [mm]", "residual_band_fraction": "residual in 0.5–3 Hz",
        "hold_mm": "hold 1/3/5 samples [mm]",
    }

    def text(v: object) -> str:
        if isinstance(v, tuple):
            return " / ".join(f"{x:g}" for x in v)
        return f"{v:g}"

    lines = [f"  {'statistic':<26}{'this':>22}{'recording':>22}"]
    for key, label in labels.items():
        if key in measured:
            lines.append(f"  {label:<26}{text(measured[key]):>22}{text(RECORDING[key]):>22}")
    return lines
