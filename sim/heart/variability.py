r"""Physiological variability of the synthetic heart motion: seeded draws with cited magnitudes.

A real heart is not a line spectrum. Five mechanisms make consecutive beats and breaths differ;
each is one group of :class:`VariabilitySettings` and each can be switched off on its own
(:meth:`VariabilitySettings.clean` switches all of them off and gives back the periodic replica
of :mod:`rhmpc.sim.heart.motion` exactly):

1. heart-rate variability,
   :math:`f_h(t) = \bar f_h(t)\,\bigl(1 + m_\text{VLF}(t) + m_\text{LF}(t) + m_\text{RSA}(t)\bigr)`:
   Gaussian processes with flat spectra in the VLF (``0.0033``–0.04 Hz) and LF (0.04–0.15 Hz)
   bands, plus respiratory sinus arrhythmia
   :math:`m_\text{RSA} = a \cos(2\pi \varphi_r(t) + \psi)` locked to the breathing phase
   :math:`\varphi_r`, which puts the HF power at the breathing rate (Task Force 1996);
2. beat-to-beat stroke variation: per-beat, per-axis gains :math:`g_i = 1 + s_i` with s an
   AR(1) series :math:`s_i = \rho\, s_{i-1} + \sigma \sqrt{1 - \rho^2}\, \varepsilon_i`, and
   a per-beat timing offset of the wall motion :math:`\delta_i` (the morphology: the same
   template shifted within the beat), AR(1) as well;
3. breathing cycles of varying period and depth: breath durations
   :math:`T_j = \bar T (1 + c_T \varepsilon_j)` and depths :math:`d_j = 1 + c_V \varepsilon_j`,
   the breathing phase :math:`\varphi_r` passing through the breath onsets;
4. slow baseline drift: a Gaussian process per axis below ``drift_cutoff``;
5. breathing–heartbeat coupling: the stroke gain
   :math:`1 + \kappa \cos(2\pi \varphi_r + \psi_\kappa)` follows the actual (variable)
   breathing phase, and the heart's position follows lung volume through the breath depths
   :math:`d_j` (the breathing term b is scaled by the depth of the current breath).

All draws use the injected :class:`numpy.random.Generator`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import PchipInterpolator, PPoly

from rhmpc.sim.heart.rr import PhaseTrack

#: Task Force of the ESC and NASPE (1996), Eur. Heart J. 17:354–381: very-low-frequency band
#: [Hz] (short-term recordings).
VLF_BAND: tuple[float, float] = (0.0033, 0.04)
#: Task Force (1996): low-frequency band [Hz].
LF_BAND: tuple[float, float] = (0.04, 0.15)
#: Task Force (1996): high-frequency band [Hz], where respiratory sinus arrhythmia appears.
HF_BAND: tuple[float, float] = (0.15, 0.40)
#: Grid of the heart-rate modulation (the usual 4 Hz tachogram resampling rate) [Hz].
TACHOGRAM_RATE = 4.0


@dataclass(frozen=True)
class VariabilitySettings:
    """Magnitudes of the five variability mechanisms (module docstring). 0 switches one off.

    Attributes
    ----------
    hrv_cv : float
        Standard deviation of the relative heart-rate modulation m [-] (≈ SDNN/mean RR).
        Task Force (1996) short-term norms (5 min, supine): total power 3466 ± 1018 ms²,
        i.e. SDNN ≈ 59 ms at a resting RR of ≈ 1 s: 0.06.
    band_powers : tuple of float
        Relative powers of the VLF, LF and HF (RSA) parts [ms², only the ratios matter]:
        Task Force short-term norms 3466 − 1170 − 975 = 1321 (VLF), 1170 (LF), 975 (HF).
    beat_gain_std : float
        σ of the per-beat, per-axis stroke gain [-] (0.03: the replicas' value before this
        module; beat-to-beat fluctuation of stroke volume of a few per cent, Appel et al.
        1989, JACC 14:1139).
    beat_gain_correlation : float
        Lag-one correlation ρ of the per-beat gains [-] (0 = independent beats, the clean
        replica). 0.3: the beat-to-beat "short-term memory" is an assumption, taken equal to
        the lag-one breath autocorrelation of tidal volume, 0.295 (Tobin et al. 1995,
        AJRCCM 152:1967).
    beat_timing_std : float
        σ of the per-beat timing offset δ_i of the wall motion within the beat [cycles].
        0.01 of a cycle ≈ 6 ms at 100 bpm: the beat-to-beat scatter of the pre-ejection
        period (systolic time intervals, a few ms; assumption of that order).
    breath_period_cv : float
        Coefficient of variation of breath duration [-]. Tobin et al. (1988), J. Appl.
        Physiol. 65:309: respiratory frequency CV ``20.8 ± 11.5`` % in 65 subjects breathing
        spontaneously at rest (0.21). The replicated animals were mechanically ventilated
        (Tuna et al. 2013 §III-B: one breathing line at 0.17 Hz with its harmonic), which
        fixes the period: default 0. With 0.21 and 0.33 (below) the reported RMS/peak-to-peak
        of ``3.55/8.39`` mm (fixed-a2-top) is out of reach (3.3 mm at most, measured): the
        paper's ratio itself says the breathing was regular.
    breath_depth_cv : float
        Coefficient of variation of breath depth (tidal volume) [-]. Tobin et al. (1988):
        V_T CV 33 ± 15 % spontaneous (0.33); a volume-controlled ventilator: default 0.
    drift_std : float
        Standard deviation of the baseline drift per axis, as a fraction of the heartbeat's
        peak-to-peak on its main axis [-]. 0.01 of ≈ 8 mm ≈ 0.1 mm, below the sonomicrometer's
        250 µm absolute accuracy (Tuna et al. 2013 §III-A), so the recordings could not have
        shown it; an assumption bounded by that accuracy.
    drift_cutoff : float
        Upper frequency of the drift's flat spectrum [Hz] (below the 0.04 Hz LF band edge).
    coupling : float
        κ, respiratory modulation of the stroke [-]: 0.08 (respiratory stroke-volume variation
        of ≈ 10–15 % peak-to-peak under mechanical ventilation, Michard & Teboul 2000, Crit.
        Care 4:282). Kept by :meth:`clean` (it is part of today's replica).
    coupling_follows_breath : bool
        True: κ's modulation follows the variable breathing phase; False: a cosine at the
        mean breathing rate (the clean replica).
    """

    hrv_cv: float = 0.06
    band_powers: tuple[float, float, float] = (1321.0, 1170.0, 975.0)
    beat_gain_std: float = 0.03
    beat_gain_correlation: float = 0.3
    beat_timing_std: float = 0.01
    breath_period_cv: float = 0.0
    breath_depth_cv: float = 0.0
    drift_std: float = 0.01
    drift_cutoff: float = 0.03
    coupling: float = 0.08
    coupling_follows_breath: bool = True

    def __post_init__(self) -> None:
        if len(self.band_powers) != 3 or not all(
                np.isfinite(p) and p >= 0 for p in self.band_powers) or sum(self.band_powers) <= 0:
            raise ValueError(f"band_powers must be three powers ≥ 0, got {self.band_powers}")
        for name in ("hrv_cv", "beat_gain_std", "beat_timing_std",
                     "breath_period_cv", "breath_depth_cv", "drift_std", "coupling"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be finite and ≥ 0, got {value}")
        if not -1.0 < self.beat_gain_correlation < 1.0:
            raise ValueError("beat_gain_correlation must be in (−1, 1), "
                             f"got {self.beat_gain_correlation}")
        if not self.drift_cutoff > 0:
            raise ValueError(f"drift_cutoff must be > 0 [Hz], got {self.drift_cutoff}")
        if self.hrv_cv >= 0.3 or self.breath_period_cv >= 0.3:
            raise ValueError("hrv_cv and breath_period_cv must stay below 0.3 (the rate "
                             "must stay positive)")

    @classmethod
    def clean(cls) -> VariabilitySettings:
        """Today's periodic replica: independent 3 % beat gains and κ = 0.08 at a fixed rate."""
        return cls(hrv_cv=0.0, beat_gain_correlation=0.0, beat_timing_std=0.0,
                   breath_period_cv=0.0, breath_depth_cv=0.0, drift_std=0.0,
                   coupling_follows_breath=False)

    @property
    def is_clean(self) -> bool:
        """True when nothing beyond the clean replica is switched on."""
        return replace(self, beat_gain_std=0.0, coupling=0.0) == replace(
            self.clean(), beat_gain_std=0.0, coupling=0.0)


def band_limited_noise(rng: np.random.Generator, n: int, rate: float,
                       band: tuple[float, float]) -> np.ndarray:
    """Zero-mean, unit-variance Gaussian series of ``n`` samples at ``rate`` [Hz] whose
    spectrum is flat in ``band`` [Hz] and zero elsewhere (random-phase FFT synthesis)."""
    n_fft = 1 << int(np.ceil(np.log2(max(n, 64))))
    f = np.fft.rfftfreq(n_fft, 1.0 / rate)
    inside = (f >= band[0]) & (f <= band[1])
    if not inside.any():  # band narrower than the resolution: the nearest bin
        inside[np.argmin(np.abs(f - 0.5 * (band[0] + band[1])))] = True
    spec = np.where(inside, rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size), 0)
    x = np.fft.irfft(spec, n_fft)[:n]
    std = float(np.std(x))
    return (x - x.mean()) / std if std > 0 else x


def variations(rng: np.random.Generator, settings: VariabilitySettings, n_beats: int, dim: int,
               breath: PhaseTrack | None, horizon: float, heart_range: float) -> dict:
    """The draws that make beats and breaths differ, in this order, as the keywords of
    :class:`~rhmpc.sim.heart.motion.SyntheticHeartMotion` (``beat_gains`` for the ``n_beats``
    beats, ``coupling_phase``, and with a breathing phase the others).

    Without ``breath`` (the clean replica): independent gains g_i = 1 + σ ε_i, ε_i ~ N(0, 1)
    clipped to ±3 (σ = ``beat_gain_std``), then ψ_κ ~ U(0, 2π). With ``breath`` (φ_r over
    [−5 s, horizon + 5 s]): the gains 1 + s_i and timing offsets δ_i as AR(1) series
    (:func:`ar1`, lag-one correlation ``beat_gain_correlation``), the depths
    d_j = 1 + c_V ε_j (ε clipped to ±2.5) of breaths ⌊φ_r(−5)⌋ … ⌈φ_r(horizon + 5)⌉, the drift
    (:func:`drift_knots`, ``drift_std`` × ``heart_range``, the heartbeat's peak-to-peak on its
    main axis [m]), then ψ_κ.
    """
    if breath is None:
        eps = np.clip(rng.standard_normal((n_beats, dim)), -3.0, 3.0)
        return {"beat_gains": 1.0 + settings.beat_gain_std * eps,
                "coupling_phase": 2 * np.pi * rng.random()}
    rho = settings.beat_gain_correlation
    gains = 1.0 + ar1(rng, n_beats, settings.beat_gain_std, rho, dim)
    offsets = ar1(rng, n_beats, settings.beat_timing_std, rho)[:, 0]
    first_breath = int(np.floor(float(breath(-5.0))))
    n_breaths = int(np.ceil(float(breath(horizon + 5.0)))) - first_breath + 1
    depths = 1.0 + settings.breath_depth_cv * np.clip(rng.standard_normal(n_breaths), -2.5, 2.5)
    drift = None
    if settings.drift_std > 0:
        drift = smooth_knots(*drift_knots(rng, horizon, dim, settings.drift_std * heart_range,
                                          settings.drift_cutoff))
    follows = settings.coupling_follows_breath or settings.breath_period_cv > 0 \
        or settings.breath_depth_cv > 0
    return {"beat_gains": gains, "coupling_phase": 2 * np.pi * rng.random(),
            "breath_phase": breath if follows else None,
            "breath_depths": depths if settings.breath_depth_cv > 0 else None,
            "first_breath": first_breath,
            "beat_offsets": offsets if settings.beat_timing_std > 0 else None, "drift": drift}


def ar1(rng: np.random.Generator, n: int, std: float, correlation: float,
        dim: int = 1) -> np.ndarray:
    """AR(1) series s_i = ρ s_{i−1} + σ√(1−ρ²) ε_i, stationary start, ε clipped to ±3: (n, dim)."""
    eps = np.clip(rng.standard_normal((n, dim)), -3.0, 3.0)
    out = np.empty((n, dim))
    out[0] = std * eps[0]
    scale = std * np.sqrt(1.0 - correlation**2)
    for i in range(1, n):
        out[i] = correlation * out[i - 1] + scale * eps[i]
    return out


def breathing_phase(rng: np.random.Generator, rate: float, horizon: float,
                    period_cv: float, phase0: float = 0.0) -> PhaseTrack:
    r"""Breathing phase φ_r(t) [cycles] through breath onsets of varying duration.

    .. math::

        T_j = \frac{1}{f_r}\,(1 + c_T \varepsilon_j), \qquad
        \varepsilon_j \sim \mathcal{N}(0, 1) \text{ clipped to } \pm 2.5, \qquad
        \varphi_r(t_j) = j - \varphi_0,

    with the PCHIP interpolant of :meth:`PhaseTrack.from_beat_times`, covering
    [−10 s, horizon + 10 s].
    """
    mean = 1.0 / rate
    n = int(np.ceil((horizon + 20.0) / (mean * (1 - 2.5 * period_cv)))) + 3
    periods = mean * (1.0 + period_cv * np.clip(rng.standard_normal(n), -2.5, 2.5))
    onsets = -10.0 - phase0 * mean + np.concatenate([[0.0], np.cumsum(periods)])
    first = -int(np.ceil(10.0 / mean))
    return PhaseTrack.from_beat_times(onsets, first_beat=first)


def modulated_phase(rng: np.random.Generator, knots_t: np.ndarray, knots_rate: np.ndarray,
                    horizon: float, settings: VariabilitySettings, breath: PhaseTrack,
                    phase0: float = 0.0) -> PhaseTrack:
    r"""Heart phase with HRV.

    .. math::

        \varphi(t) = \varphi_0 + \int \bar f_h(\tau)\,
            \bigl(1 + m_\text{VLF} + m_\text{LF} + m_\text{RSA}\bigr)(\tau)\,d\tau

    The nominal profile :math:`\bar f_h` (piecewise linear through ``knots_t``, ``knots_rate``)
    is sampled on a 4 Hz grid over [−10 s, horizon + 10 s], multiplied by 1 + m and integrated
    exactly as a piecewise-linear rate. The parts have variances
    :math:`\mathrm{cv}^2 P_b / \sum P` (``band_powers`` P, cv = ``hrv_cv``);
    :math:`m_\text{RSA} = a \cos(2\pi \varphi_r + \psi)` with :math:`a^2/2` its variance.
    """
    t = np.arange(-10.0, horizon + 10.0 + 1.0 / TACHOGRAM_RATE, 1.0 / TACHOGRAM_RATE)
    nominal = np.interp(t, knots_t, knots_rate)
    share = np.asarray(settings.band_powers, dtype=float) / sum(settings.band_powers)
    std = settings.hrv_cv * np.sqrt(share)
    m = (std[0] * band_limited_noise(rng, t.size, TACHOGRAM_RATE, VLF_BAND)
         + std[1] * band_limited_noise(rng, t.size, TACHOGRAM_RATE, LF_BAND)
         + std[2] * np.sqrt(2.0) * np.cos(2 * np.pi * breath(t) + 2 * np.pi * rng.random()))
    rate = nominal * np.maximum(1.0 + m, 0.3)
    at_zero = float(PhaseTrack.from_rate_knots(t, rate, 0.0)(0.0))
    return PhaseTrack.from_rate_knots(t, rate, phase0 - at_zero)


def drift_knots(rng: np.random.Generator, horizon: float, dim: int, std: float,
                cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """Baseline drift per axis on a 1 Hz grid over [−10 s, horizon + 10 s]: (t, values (n, dim))
    with each axis a unit-shape Gaussian process flat below ``cutoff`` scaled to ``std``."""
    t = np.arange(-10.0, horizon + 11.0, 1.0)
    values = np.stack([std * band_limited_noise(rng, t.size, 1.0, (0.0, cutoff))
                       for _ in range(dim)], axis=1)
    return t, values


def smooth_knots(t: np.ndarray, values: np.ndarray) -> PPoly:
    """PCHIP through (t, values (n, dim)) as a PPoly (smooth drift, no kinks at the knots)."""
    p = PchipInterpolator(t, values, axis=0, extrapolate=True)
    return PPoly(p.c, p.x, extrapolate=True)
