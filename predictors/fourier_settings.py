"""Settings of the Fourier-series EKFs and their named parameter sets.

:class:`EKFSettings` is the quasi-periodic EKF's (:mod:`rhmpc.predictors.ekf_fourier`, Yuen et al.
2008; Tuna et al. 2013), :class:`DualEKFSettings` the dual respiratory + cardiac EKF's
(:mod:`rhmpc.predictors.ekf_dual_fourier`, Richa et al. 2010). Each predictor's ``PARAMETER_SETS``
keeps the papers' settings by name beside its default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from rhmpc.predictors.base import PredictorSettings

__all__ = ["DUAL_PARAMETER_SETS", "EKF_PARAMETER_SETS", "Q_OMEGA_HRV", "DualEKFSettings",
           "EKFSettings"]

_TWO_PI = 2.0 * math.pi


def _positive(settings, *names: str) -> None:
    for name in names:
        if not getattr(settings, name) > 0.0:
            raise ValueError(f"{name} must be > 0, got {getattr(settings, name)!r}")


def _nonnegative(settings, *names: str, optional: bool = False) -> None:
    for name in names:
        v = getattr(settings, name)
        if not (optional and v is None) and not v >= 0.0:
            raise ValueError(f"{name} must be >= 0{' or None' if optional else ''}, got {v!r}")


def _integers(settings, low: int, *names: str) -> None:
    for name in names:
        v = getattr(settings, name)
        if int(v) != v or v < low:
            raise ValueError(f"{name} must be an integer >= {low}, got {v!r}")


def _bands(settings, *names: str) -> None:
    for name in names:
        lo, hi = getattr(settings, name)
        if not 0.0 < lo < hi:
            raise ValueError(f"{name} must be (low, high) with 0 < low < high [Hz]")


def _shared(settings) -> None:
    """The checks of the settings both EKFs have: the gate, the rate of the process variances
    and the non-periodic part."""
    if settings.gate_probability is not None and not 0.0 < settings.gate_probability < 1.0:
        raise ValueError(
            f"gate_probability must be in (0, 1) or None, got {settings.gate_probability!r}")
    if not settings.gate_seconds > 0.0:
        raise ValueError(f"gate_seconds must be > 0, got {settings.gate_seconds!r}")
    if settings.q_rate_hz is not None and not settings.q_rate_hz > 0.0:
        raise ValueError(f"q_rate_hz must be > 0 or None, got {settings.q_rate_hz!r}")
    _integers(settings, 0, "residual_order", "fit_beats")
    if settings.rate_band is not None and not settings.rate_band > 1.0:
        raise ValueError(f"rate_band must be > 1 or None, got {settings.rate_band!r}")
    if not 0.0 < settings.residual_forgetting <= 1.0:
        raise ValueError(
            f"residual_forgetting must be in (0, 1], got {settings.residual_forgetting!r}")


@dataclass(frozen=True)
class EKFSettings(PredictorSettings):
    """Fourier-series EKF settings; defaults are Tuna et al. 2013's (``tuna2013``).

    Attributes
    ----------
    harmonics : int
        m, harmonics per axis [-].
    init_seconds : float
        Length of the FFT + least-squares initialisation window [s] (N = init_seconds/dt),
        also of the re-fit after a lost lock.
    sigma_r : float
        σ_R, measurement noise standard deviation [m].
    sigma1_sq : float
        σ₁², initial variance of the first harmonic amplitude [m²]; σ₁²/i² for the i-th.
    sigma_omega_sq : float
        σ_ω², initial variance of ω [(rad/s)²].
    sigma_phase_sq : float
        Initial variance of each phase [rad²].
    q : float
        Process noise of c and r_i [m² per sample].
    q_phase : float
        Process noise of each phase [rad² per sample].
    q_omega : float
        Process noise of ω, q_ω [(rad/s)² per sample].
    band_hz : tuple of float
        Heart-rate band searched by the FFT [Hz]: 36–180 beats/min, which holds the
        95–152 beats/min pacemaker staircase of Tuna §III-B; ω̂ outside it triggers the re-fit.
    omega_limits_hz : tuple of float
        ω̂ is clamped to this range [Hz] (counted ``omega_clamped``), then re-fitted.
    gate_probability : float or None
        Innovation gate: samples with NIS above the χ²_d quantile of this probability are
        rejected [-]; ``None``: no gate (Yuen's filter).
    gate_seconds : float
        Longest run of rejected samples [s]; then samples are used again.
    breathing_harmonics : int
        H_b, respiratory harmonics in the state [-]; 0 = Yuen's model without breathing.
    breathing_band_hz : tuple of float
        Respiratory band [Hz] (6–30 breaths/min): FFT search and clamp of ω̂_b.
    q_breathing : float
        Process noise of the respiratory coefficients [m² per sample at Richa's ``83.3`` Hz]
        (Richa §I-D: 1e-5 mm²).
    q_omega_breathing : float
        Process noise of ω_b [(rad/s)² per sample at Richa's ``83.3`` Hz] (Richa: 1e-8
        (rad/sample)²).
    q_omega_per_second : float or None
        Process noise intensity of ω [(rad/s)² per second]; if given it replaces
        ``q_omega`` by ``q_omega_per_second · Δt`` (rate-independent).  ``tuna2013-hrv``
        derives it from heart-rate variability (see ``PARAMETER_SETS``).
    q_rate_hz : float or None
        Sample rate at which q, q_phase, q_omega were tuned [Hz].  ``None``: they are
        per sample at the predictor's own rate.  Otherwise they are rescaled by
        ``dt · q_rate_hz`` so that the random walks diffuse as fast per second as in
        the paper (Yuen's are per sample at 28 Hz).
    adaptive_r : bool
        R follows the residual of the current state over the last beat (covariance matching
        with the residual's long-run variance, :mod:`rhmpc.predictors.nonperiodic`); σ_R² is its
        floor and start.  False: R = σ_R² (Yuen, Tuna).
    residual_order : int
        p of the autoregression of the residual (:mod:`rhmpc.predictors.residual`); 0: none.
    residual_forgetting : float
        λ of its RLS [-] (0.999: the RLS predictors' default).
    p0_from_fit : bool
        P(T|T) of c, r, θ and the breathing coefficients from the least-squares covariance of
        the window fit, s²_lr·(AᵀA)⁻¹, s²_lr the fit residual's long-run variance per axis
        (module docstring), instead of Yuen's diag[σ_R²/N, σ₁²/i², σ_θ²].
    fit_beats : int
        c, r, θ are fitted on the last ``fit_beats`` beats of the window (its breathing fit
        removed, ω̂₀ from the whole window's FFT); 0: the whole window (Yuen).
    rate_band : float or None
        b: ω̂ leaving [ω₀/b, ω₀·b] around the rate ω₀ of the last fit is a lost lock (re-fit,
        module docstring); ``None``: only the FFT's band.
    unit : float or None
        Metres per data unit (1.0 for samples in m, 1e-3 for mm); ``None``: inferred.
    """

    harmonics: int = 5
    init_seconds: float = 10.0
    sigma_r: float = 0.3e-3
    sigma1_sq: float = 1.0e-6
    sigma_omega_sq: float = 0.10
    sigma_phase_sq: float = 1e-3
    q: float = 1e-3 * 1e-6
    q_phase: float = 1e-3
    q_omega: float = 5e-3
    band_hz: tuple[float, float] = field(default=(0.6, 3.0))
    omega_limits_hz: tuple[float, float] = field(default=(0.5, 3.5))
    gate_probability: float | None = 1.0 - 1e-6
    gate_seconds: float = 0.1
    breathing_harmonics: int = 2
    breathing_band_hz: tuple[float, float] = field(default=(0.08, 0.5))
    q_breathing: float = 1e-5 * 1e-6
    q_omega_breathing: float = 1e-8 * 83.3**2
    q_omega_per_second: float | None = None
    q_rate_hz: float | None = None
    adaptive_r: bool = False
    residual_order: int = 0
    residual_forgetting: float = 0.999
    p0_from_fit: bool = False
    fit_beats: int = 0
    rate_band: float | None = None
    unit: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        _integers(self, 1, "harmonics")
        _integers(self, 0, "breathing_harmonics")
        _positive(self, "init_seconds", "sigma_r", "sigma1_sq", "sigma_omega_sq")
        _nonnegative(self, "sigma_phase_sq", "q", "q_phase", "q_omega", "q_breathing",
                     "q_omega_breathing")
        _nonnegative(self, "q_omega_per_second", optional=True)
        _bands(self, "band_hz", "omega_limits_hz", "breathing_band_hz")
        _shared(self)


MM, MM2 = 1e-3, 1e-6  # metres per millimetre, m² per mm²

#: HRV magnitude used for ``tuna2013-hrv``: short-term RR coefficient of variation [-]
#: (6 %, the variability of ``sim/heart/variability.py``; resting humans 3–7 %), at the replicas'
#: mean heart rate [Hz] (≈ 96 bpm; Tuna §III-B 95–152 bpm) over one ventilator breath [s]
#: (0.17 Hz, Tuna/Richa's ventilated animals).
HRV_CV, HRV_HEART_HZ, HRV_BREATH_S = 0.06, 1.6, 1.0 / 0.17
#: RSA takes the rate from its trough to its peak within half a breath [s].
HRV_RISE_S = 0.5 * HRV_BREATH_S
#: q_ω [(rad/s)²/s] such that the random walk of ω spreads by one HRV standard deviation
#: σ_ω = 2π·CV·f_h in the time RSA takes to swing the rate from trough to peak (half a
#: breath): q_ω·T_b/2 = σ_ω² (≈ 0.124 (rad/s)²/s; 9.6e-4 per sample at 128.5 Hz).
Q_OMEGA_HRV = (_TWO_PI * HRV_CV * HRV_HEART_HZ) ** 2 / HRV_RISE_S

#: Parameter sets.  ``yuen2008``: Yuen et al. 2008 §III-A/D (noise study; σ_R is
#: the 3DUS uncertainty 1.3 mm, set it to the simulated noise).  ``tuna2013``: Tuna et al.
#: 2013 §VIII-C, tuned for the 3-D sonomicrometry tracking experiments; Tuna do not give the
#: rate, we take it to be per sample of the 133 Hz predictor (``q_rate_hz=None``).
#: ``tuna2013-hrv``: Tuna's set with q_ω from heart-rate variability,
#: ``Q_OMEGA_HRV``.  Tuna's q_ω = 5e-3 (rad/s)² per 128.5 Hz sample (0.64
#: (rad/s)²/s, 10× the HRV value) lets the breathing residual walk ω̂ to its 0.5 Hz clamp
#: within 3 s on fixed-a1-top and varying-a3-side; the HRV value keeps lock on all six
#: replicas (RMS of ω̂ − ω 2.4–3.1 bpm), and anything in 2e-4–2e-3 per sample does.
EKF_PARAMETER_SETS: dict[str, EKFSettings] = {
    "yuen2008": EKFSettings(
        harmonics=8,
        init_seconds=10.0,
        sigma_r=1.3 * MM,
        sigma1_sq=2.0 * MM2,
        sigma_omega_sq=0.11,
        sigma_phase_sq=0.02,
        q=1e-4 * MM2,
        q_phase=1e-4,
        q_omega=1e-3,
        q_rate_hz=28.0,
        band_hz=(0.5, 2.5),
        breathing_harmonics=0,
        gate_probability=None,
    ),
    "tuna2013": EKFSettings(
        harmonics=5,
        init_seconds=10.0,
        sigma_r=0.3 * MM,
        sigma1_sq=1.0 * MM2,
        sigma_omega_sq=0.10,
        sigma_phase_sq=1e-3,
        q=1e-3 * MM2,
        q_phase=1e-3,
        q_omega=5e-3,
    ),
}
EKF_PARAMETER_SETS["tuna2013-hrv"] = EKFSettings(q_omega_per_second=Q_OMEGA_HRV)
#: ``adaptive`` (the ``ekf`` default): ``tuna2013-hrv`` with the non-periodic part (module
#: docstring, "Motion that is not periodic"): R from the data, the residual's AR(16) (Tuna's
#: one-step order), the fit started from its own covariance on its last 3 beats, and ω̂
#: held within 1.5× of the fitted rate.
EKF_PARAMETER_SETS["adaptive"] = EKFSettings(
    q_omega_per_second=Q_OMEGA_HRV, adaptive_r=True, residual_order=16, p0_from_fit=True,
    fit_beats=3, rate_band=1.5)


@dataclass(frozen=True)
class DualEKFSettings(PredictorSettings):
    """Dual Fourier EKF settings (defaults: Richa et al. 2010; initial frequencies: Tuna §III-B).

    Attributes
    ----------
    respiratory_harmonics, cardiac_harmonics : int
        H_r, H_c [-].
    respiratory_hz, cardiac_hz : float
        Initial frequencies [Hz] (Richa take them from the ventilator and the ECG).
    q_respiratory, q_offset, q_cardiac : float
        Process variances of the coefficients [m² per sample at ``q_rate_hz``].
    q_omega : float
        Process variance of each frequency [(rad/s)² per sample at ``q_rate_hz``].
    q_omega_respiratory : float or None
        Process variance of ω_r alone [(rad/s)² per sample at ``q_rate_hz``]; ``None``:
        ``q_omega`` (Richa).  Default 1e-10 (rad/sample)² at ``q_rate_hz``, 1 % of Richa's:
        a ventilator holds the rate constant, so ω̂_r need only converge from the
        initialisation (prior ``p0_omega_respiratory``); the walk spreads by 0.6
        breaths/min in a minute.
    q_omega_cardiac_per_second : float or None
        Process noise intensity of ω_c [(rad/s)² per second], replacing ``q_omega`` for
        ω_c; ``None``: ``q_omega`` (Richa).  Default: heart-rate variability,
        :data:`rhmpc.predictors.ekf_fourier.Q_OMEGA_HRV` (≈ 0.124 (rad/s)²/s, 21× Richa's), as
        the ``ekf``'s ``tuna2013-hrv``.
    q_phase_cardiac_per_second : float or None
        Phase walk of every cardiac harmonic [rad² per second], ``None``: none (Richa).  As
        the ``ekf``'s per-harmonic phase noise (Yuen's φ_{a,i}), in this filter's sin/cos
        coordinates: d_h sin hθ + e_h cos hθ = r_h sin(hθ + φ_h), a phase step δ moves
        (d_h, e_h) by δ·(−e_h, d_h), so each axis's (d_h, e_h) block of P gains
        q_φΔt·[[e_h², −d_he_h], [−d_he_h, d_h²]] per sample.  Off by default; Tuna 2013
        §VIII-C gives 1e-3 rad² per 133-Hz sample, Yuen 2008 1e-4 per 28-Hz sample.
    r : float
        Measurement variance per axis [m²].
    p0_coefficient : float
        Initial variance of every coefficient (not the offset) [m²]; after the fitted start
        only of the cardiac ones, unless ``p0_respiratory_from_fit`` is off.
    p0_respiratory_from_fit : bool
        After the least-squares initialisation, start the respiratory coefficients and the
        offset at the fit's own covariance s_a²·(ΦᵀΦ)⁻¹ (their block, per axis) instead of
        ``p0_coefficient`` / ``p0_offset``; the cardiac coefficients keep ``p0_coefficient``.
    p0_omega_respiratory, p0_omega_cardiac : float
        Initial variances of the two frequencies [(rad/s)²]: (2π·0.01 Hz)² and (2π·0.05 Hz)²;
        a loose respiratory prior lets ω_r slide to a subharmonic.
    q_rate_hz : float or None
        Rate the process variances are given at [Hz] (Richa's ``83.3``); ``None`` = per own
        sample.
    omega_limits_hz : tuple of float
        Both frequencies are clamped to this range [Hz].
    gate_probability : float or None
        Innovation gate probability [-] (χ²_d quantile); ``None``: no gate (Richa).
    gate_seconds : float
        Longest run of rejected samples [s]; then samples are used again.
    init_seconds : float or None
        Length of the FFT + least-squares initialisation window [s] (≥ one breath), also of
        the re-fit after a lost lock; ``None``: Richa's start (zero coefficients, the given
        frequencies), no re-fit.
    respiratory_known : bool
        The initialisation takes ω_r = 2π·``respiratory_hz`` (the ventilator's set rate, as
        Richa) instead of the FFT peak in ``respiratory_band_hz``, which a 10 s window of
        1.7 breaths resolves only to ±0.05 Hz.
    respiratory_band_hz, cardiac_band_hz : tuple of float
        FFT search bands of the initialisation [Hz] (6–30 breaths/min; 36–180 beats/min,
        as the EKF's); a frequency estimate outside its band triggers the re-fit.
    adaptive_r : bool
        R follows the residual of the current state over the last beat
        (:mod:`rhmpc.predictors.nonperiodic`), ``r`` its floor and start; False: R = ``r``.
    residual_order : int
        p of the autoregression of the residual (:mod:`rhmpc.predictors.residual`); 0: none.
    residual_forgetting : float
        λ of its RLS [-].
    p0_cardiac_from_fit : bool
        After the fit, the cardiac coefficients start at the least-squares covariance too,
        with the long-run variance of the fit's residual (as the ``ekf``'s ``p0_from_fit``)
        instead of ``p0_coefficient``.
    fit_beats : int
        The cardiac coefficients and the offset are fitted again on the window's last
        ``fit_beats`` beats (its respiratory fit removed); 0: the whole window.
    rate_band : float or None
        b: ω̂_c leaving [ω₀/b, ω₀·b] around the cardiac rate ω₀ of the last fit is a lost lock
        (re-fit); ``None``: only ``cardiac_band_hz``.
    unit : float or None
        Metres per data unit; ``None``: inferred from the data (see ``rhmpc.predictors.base``).
    """

    respiratory_harmonics: int = 3
    cardiac_harmonics: int = 5
    respiratory_hz: float = 0.17
    cardiac_hz: float = 1.66
    q_respiratory: float = 1e-5 * 1e-6
    q_offset: float = 1e-6 * 1e-6
    q_cardiac: float = 1e-5 * 1e-6
    q_omega: float = 1e-8 * 83.3**2
    q_omega_respiratory: float | None = 1e-10 * 83.3**2
    q_omega_cardiac_per_second: float | None = Q_OMEGA_HRV
    q_phase_cardiac_per_second: float | None = None
    r: float = 0.1 * 1e-6
    p0_coefficient: float = 25e-6
    p0_respiratory_from_fit: bool = True
    p0_offset: float = 1e-6
    p0_omega_respiratory: float = (_TWO_PI * 0.01) ** 2
    p0_omega_cardiac: float = (_TWO_PI * 0.05) ** 2
    q_rate_hz: float | None = 83.3
    omega_limits_hz: tuple[float, float] = (0.02, 5.0)
    gate_probability: float | None = 1.0 - 1e-6
    gate_seconds: float = 0.1
    init_seconds: float | None = 10.0
    respiratory_known: bool = False
    respiratory_band_hz: tuple[float, float] = (0.08, 0.5)
    cardiac_band_hz: tuple[float, float] = (0.6, 3.0)
    adaptive_r: bool = False
    residual_order: int = 0
    residual_forgetting: float = 0.999
    p0_cardiac_from_fit: bool = False
    fit_beats: int = 0
    rate_band: float | None = None
    unit: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        _integers(self, 1, "respiratory_harmonics", "cardiac_harmonics")
        _positive(self, "respiratory_hz", "cardiac_hz", "r", "p0_coefficient", "p0_offset")
        _nonnegative(self, "q_respiratory", "q_offset", "q_cardiac", "q_omega",
                     "p0_omega_respiratory", "p0_omega_cardiac")
        _nonnegative(self, "q_omega_respiratory", "q_omega_cardiac_per_second",
                     "q_phase_cardiac_per_second", optional=True)
        if self.init_seconds is not None and not self.init_seconds > 0.0:
            raise ValueError(f"init_seconds must be > 0 or None, got {self.init_seconds!r}")
        _bands(self, "respiratory_band_hz", "cardiac_band_hz")
        _shared(self)


#: Parameter sets.  ``richa2010``: Richa et al. 2010 §I-C/D as published (zero start at the
#: given frequencies, Richa's process variances for both frequencies, no gate, no re-fit).
#: ``fitted``: the fitted start, HRV-sized q_ω_c, the ventilator-held q_ω_r and the innovation
#: gate (this module's docstring).  ``adaptive`` (the ``dual-ekf`` default): ``fitted`` with the
#: non-periodic part of :mod:`rhmpc.predictors.nonperiodic` (R from the current state's residual
#: over the last beat, the residual's AR(16)), the cardiac series fitted on the last 3 beats
#: and ω̂_c held within 1.5× of the fitted rate (module docstring, "Motion that is not
#: periodic").
DUAL_PARAMETER_SETS: dict[str, DualEKFSettings] = {
    "richa2010": DualEKFSettings(init_seconds=None, q_omega_respiratory=None,
                                 q_omega_cardiac_per_second=None, gate_probability=None),
    "fitted": DualEKFSettings(),
    "adaptive": DualEKFSettings(adaptive_r=True, residual_order=16, fit_beats=3,
                                rate_band=1.5),
}
