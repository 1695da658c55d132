"""Dual (respiratory + cardiac) time-varying Fourier-series EKF (Richa, Bó & Poignet 2010, §I-C/D).

Model, per axis (eq. 1), two frequencies shared by all axes:

    y(t) = c_r + Σ_{h=1}^{H_r} [a_h sin hθ_r + b_h cos hθ_r]
               + Σ_{h=1}^{H_c} [d_h sin hθ_c + e_h cos hθ_c],

θ_r, θ_c the accumulated phases (θ ← θ + ωΔt, Richa's Σ_k ω(k)).  All coefficients
and both frequencies are random walks (eq. 2, P⁻ = P + Q); the EKF correction is
eqs. (3)–(5) with C = ∂y/∂x.  Deviation from the paper: the two accumulated phases
are carried as (noise-free) states, so that the frequency enters through the
transition F (θ += ωΔt) and its Jacobian is exact; with the phases held outside the
state Richa's identity transition is recovered.  The offset c_r starts at the first
sample instead of 0 (samples in a robot frame are far from 0); everything else
starts at zero and the frequencies at their given initial values, as in Richa
(``init_seconds=None``).

Initialisation (issue 18, default ``init_seconds`` = 10 s): as Yuen's EKF
(:func:`predictors.fourier_init.initial_dual_state`), the first ``init_seconds`` of samples
give ω̂_r by FFT in ``respiratory_band_hz``, then (the respiratory fit removed) ω̂_c in
``cardiac_band_hz``, and c_r, a, b, d, e by least squares with θ_r = θ_c = 0 at the newest
sample; the forecast holds the newest sample until then.  Richa's zero start fails on
3-D replicas: over the first breath the respiratory sin/cos are nearly collinear with the
offset, the coefficients grow to ±10–18 mm in opposite signs and their phase
sensitivity drags ω̂_r to 40 breaths/min and ω̂_c to its clamp within 4 s
(varying-a1-top, varying-a3-top).  A window of at least one breath makes them
identifiable.

Initial covariance after the fit (issue 18, physical sonomicrometer stream): the
respiratory coefficients and the offset start at the least-squares covariance of the window
fit, s_a²·(ΦᵀΦ)⁻¹ (their block; s_a² the fit's residual variance on axis a), the cardiac ones
at ``p0_coefficient``.  With the flat priors (25 mm² on every coefficient, 1 mm² on the offset,
meant for Richa's zero start) the first innovations after the fit re-fitted the breathing:
on varying-a1-side the respiratory coefficients moved by 9–14 mm and the offset by 8.7 mm
within 2 s (against 0.1 mm with the fit's covariance), the near-collinearity of the slow
respiratory sin/cos with the offset over a fraction of a breath again, and ω̂_c went
92 → 102 bpm while the heart rate went 80 → 91; the gate then rejected a third of the
samples and ω̂_c ran to its clamp (436 clamps, 3-step RMS 4.18 mm against hold's 1.16).
A window of 1.7 breaths does determine the breathing to its covariance (the ventilator
holds the rate: ``q_omega_respiratory``).  The cardiac fit is not held to its
covariance: the heart rate at the window's end differs from the window's FFT rate by up to the
respiratory swing (7–12 bpm measured), which a fixed-rate fit's covariance does not know;
holding the cardiac coefficients to it as well keeps lock but lets the gate reject the first
seconds (3-step RMS 0.44 instead of 0.32 mm on fixed-a1-top, 0.48 instead of 0.21 on
varying-a3-side).

Parameters (Richa §I-D): H_r = 3, H_c = 5; process variances 1e-5 mm² (respiratory
coefficients), 1e-6 mm² (offset), 1e-5 mm² (cardiac coefficients), 1e-8 (rad/sample)²
(frequencies), R = 0.1 mm², all per sample at Richa's 83.3 Hz.  Stored here in SI:
m², and (rad/s)² for the frequencies (1e-8·83.3² = 6.94e-5), rescaled to the
predictor's rate by ``dt · q_rate_hz``.  Initial covariance: not given by Richa;
ours is ``p0_coefficient``, ``p0_offset`` and ``p0_omega_*``.

Outliers (issue 18, as :mod:`predictors.ekf_fourier`): a sample whose normalised innovation
squared exceeds the χ²_d quantile ``gate_probability`` is not used (counted
``innovation_rejected``); after ``gate_seconds`` of consecutive rejections samples are used
again.  With the HRV-sized q_ω of ω_c an ungated 5 mm echo outlier pulls ω̂_c to its clamp
(varying-a1-side, sensor seed 5).

Re-fit on lost lock (issue 18, premature beats): with ``init_seconds`` set, the last
``init_seconds`` of samples are kept; when after an update

    ω̂_c ∉ 2π·``cardiac_band_hz``  or  ω̂_r ∉ 2π·``respiratory_band_hz``

(outside the rate range the initialisation's FFT searches, 36–180 beats/min and 6–30
breaths/min: no heart or breath the filter models) the state and covariance are re-fitted
from that window as at the start (counted ``lock_refit``); no new parameter.  Richa observe
that an arrhythmia "is interpreted as a drastic phase change" (§II-C); an EKF linearised in
the phase can lose lock on it.  Measured on MIT-BIH record 100 from t = 1200 s (atrial
premature beats at 4.5, 10.9, 28.9 s; 133 Hz stream, seeds 4/5, 30 s, scored from 15 s):
without the re-fit the premature beat 0.9 s after the fit took ω̂_c 75 → 92 → 46 beats/min
and then to its clamp on 5 of 6 replicas (3-step RMS 2.4–3.5 × hold's); with it, one re-fit
each (fixed-a2-top: 2.6 s after the beat), 0.49–0.59 × hold's, no clamp.  While both
estimates stay in their bands (every locked run) nothing changes: the issue-18 bench tables
are bit-identical.

Motion that is not periodic (``adaptive``, the default parameter set).  As the ``ekf``'s
(:mod:`predictors.ekf_fourier`): R follows the long-run variance of the current state's
residual over the last beat less H P⁻ Hᵀ (``adaptive_r``, :mod:`predictors.nonperiodic`), an
AR(16) model of that residual with the model's increments as input adds to the forecast
(``residual_order``), the offset and cardiac series are fitted again on the window's last 3
beats (``fit_beats``), and ω̂_c leaving [ω₀/1.5, 1.5 ω₀] of the fitted ω₀ is a lost lock
(``rate_band``).  Measured (25 Hz, 60 s, seed 2; ratio to hold's error at 1 / 3 / 5
samples): ``invivo-video`` 1.36 / 0.94 / 0.77 with ``fitted``, 0.75 / 0.86 / 0.79 with the
first two, 0.68 / 0.72 / 0.64 with the third (seeds 1–7: at most 0.93 at 3 samples); the six
replicas 0.17–0.21 / 0.10–0.13 / 0.10–0.13 (``fitted`` 0.19–0.25 / 0.11–0.14 / 0.10–0.14);
the 128 Hz sonomicrometry stream of fixed-a2-top, 3 samples: 0.26 (0.34).  The ``ekf``'s
``p0_from_fit`` for the cardiac coefficients (``p0_cardiac_from_fit``) is not used: 0.26 /
0.15 / 0.13 instead of 0.20 / 0.12 / 0.11 on fixed-a1-top.  ``rate_band`` changed nothing on
these streams; it is the ``ekf``'s guard against a start far from the heart rate.

Cost per update: O(n²·d) with n = d(2H_r + 2H_c + 1) + 4 (55 for d = 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from predictors.base import Predictor, PredictorSettings
from predictors.ekf_fourier import Q_OMEGA_HRV
from predictors.fourier_init import (
    FitWindow,
    fit_harmonics,
    initial_dual_state,
    spd_inverse,
    wrap_phase,
)
from predictors.nonperiodic import NonPeriodic, long_run_variance

__all__ = ["PARAMETER_SETS", "DualEKFSettings", "DualFourierEKF"]

_TWO_PI = 2.0 * math.pi


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
        ``q_omega`` (Richa).  Default 1e-10 (rad/sample)² at 83.3 Hz, 1 % of Richa's: a
        ventilator holds the rate constant, so ω̂_r need only converge from the
        initialisation (prior ``p0_omega_respiratory``); the walk spreads by 0.6
        breaths/min in a minute.  With Richa's value ω̂_r wanders to 1–6 breaths/min on
        varying-a3-top (clamped 430 times).
    q_omega_cardiac_per_second : float or None
        Process noise intensity of ω_c [(rad/s)² per second], replacing ``q_omega`` for
        ω_c; ``None``: ``q_omega`` (Richa).  Default: heart-rate variability,
        :data:`predictors.ekf_fourier.Q_OMEGA_HRV` (≈ 0.124 (rad/s)²/s, 21× Richa's), as
        the ``ekf``'s ``tuna2013-hrv``.
    q_phase_cardiac_per_second : float or None
        Phase walk of every cardiac harmonic [rad² per second], ``None``: none (Richa).  As
        the ``ekf``'s per-harmonic phase noise (Yuen's φ_{a,i}), in this filter's sin/cos
        coordinates: d_h sin hθ + e_h cos hθ = r_h sin(hθ + φ_h), a phase step δ moves
        (d_h, e_h) by δ·(−e_h, d_h), so each axis's (d_h, e_h) block of P gains
        q_φΔt·[[e_h², −d_he_h], [−d_he_h, d_h²]] per sample.  Off by default; Tuna 2013
        §VIII-C's 1e-3 rad² per 133 Hz sample (0.133 rad²/s) follows atrial premature beats
        better (record 100 from 150 s: 3-step RMS 0.58–0.74 instead of 0.79–0.96 mm on the
        a1 replicas, hold 0.84–0.95) but costs 11–18 % on the variable replicas (0.38
        instead of 0.32 mm on fixed-a1-top), and from 1500 s (one premature beat at 18.4 s,
        30 s at 133 Hz) it is mixed: 0.83–1.32 × hold's, a re-fit on all six, against
        0.72–1.66 × and two re-fits without.  Yuen 2008's 1e-4 per 28 Hz sample
        (2.8e-3 rad²/s): +1–4 % on the variable replicas and worse on premature beats
        (0.94–1.27 mm from 150 s).
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
        Rate the process variances are given at [Hz] (Richa: 83.3); ``None`` = per own sample.
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
        1.7 breaths resolves only to ±0.05 Hz (14.7 instead of 10 breaths/min on
        varying-a1-side).
    respiratory_band_hz, cardiac_band_hz : tuple of float
        FFT search bands of the initialisation [Hz] (6–30 breaths/min; 36–180 beats/min,
        as the EKF's); a frequency estimate outside its band triggers the re-fit.
    adaptive_r : bool
        R follows the residual of the current state over the last beat
        (:mod:`predictors.nonperiodic`), ``r`` its floor and start; False: R = ``r``.
    residual_order : int
        p of the autoregression of the residual (:mod:`predictors.residual`); 0: none.
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
        Metres per data unit; ``None``: inferred from the data (see ``predictors.base``).
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
        for name in ("respiratory_harmonics", "cardiac_harmonics"):
            v = getattr(self, name)
            if int(v) != v or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        for name in ("respiratory_hz", "cardiac_hz", "r", "p0_coefficient", "p0_offset"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in (
            "q_respiratory",
            "q_offset",
            "q_cardiac",
            "q_omega",
            "p0_omega_respiratory",
            "p0_omega_cardiac",
        ):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.q_rate_hz is not None and not self.q_rate_hz > 0.0:
            raise ValueError(f"q_rate_hz must be > 0 or None, got {self.q_rate_hz!r}")
        for name in (
            "q_omega_respiratory",
            "q_omega_cardiac_per_second",
            "q_phase_cardiac_per_second",
        ):
            v = getattr(self, name)
            if v is not None and not v >= 0.0:
                raise ValueError(f"{name} must be >= 0 or None, got {v!r}")
        if self.gate_probability is not None and not 0.0 < self.gate_probability < 1.0:
            raise ValueError(
                f"gate_probability must be in (0, 1) or None, got {self.gate_probability!r}"
            )
        if not self.gate_seconds > 0.0:
            raise ValueError(f"gate_seconds must be > 0, got {self.gate_seconds!r}")
        if self.init_seconds is not None and not self.init_seconds > 0.0:
            raise ValueError(f"init_seconds must be > 0 or None, got {self.init_seconds!r}")
        for name in ("respiratory_band_hz", "cardiac_band_hz"):
            lo, hi = getattr(self, name)
            if not 0.0 < lo < hi:
                raise ValueError(f"{name} must be (low, high) with 0 < low < high [Hz]")
        for name in ("residual_order", "fit_beats"):
            v = getattr(self, name)
            if int(v) != v or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
        if self.rate_band is not None and not self.rate_band > 1.0:
            raise ValueError(f"rate_band must be > 1 or None, got {self.rate_band!r}")


#: Parameter sets.  ``richa2010``: Richa et al. 2010 §I-C/D as published (zero start at the
#: given frequencies, Richa's process variances for both frequencies, no gate, no re-fit).
#: ``fitted``: the fitted start, HRV-sized q_ω_c, the ventilator-held q_ω_r and the innovation
#: gate (this module's docstring).  ``adaptive`` (the ``dual-ekf`` default): ``fitted`` with the
#: non-periodic part of :mod:`predictors.nonperiodic` (R from the current state's residual
#: over the last beat, the residual's AR(16)), the cardiac series fitted on the last 3 beats
#: and ω̂_c held within 1.5× of the fitted rate (module docstring, "Motion that is not
#: periodic").
PARAMETER_SETS: dict[str, DualEKFSettings] = {
    "richa2010": DualEKFSettings(init_seconds=None, q_omega_respiratory=None,
                                 q_omega_cardiac_per_second=None, gate_probability=None),
    "fitted": DualEKFSettings(),
    "adaptive": DualEKFSettings(adaptive_r=True, residual_order=16, fit_beats=3,
                                rate_band=1.5),
}


class DualFourierEKF(Predictor):
    """Richa's dual time-varying Fourier-series EKF, 1-D or 3-D (shared ω_r, ω_c)."""

    Settings = DualEKFSettings
    PRESETS = PARAMETER_SETS

    def _allocate(self, d: int) -> None:
        s = self.settings
        hr, hc = s.respiratory_harmonics, s.cardiac_harmonics
        self.k = k = 2 * hr + 1 + 2 * hc  # coefficients per axis: a, b, c_r, d, e
        self.nx = d * k + 4  # + ω_r, ω_c, θ_r, θ_c
        self.iwr, self.iwc, self.itr, self.itc = d * k, d * k + 1, d * k + 2, d * k + 3
        self._hr = np.arange(1.0, hr + 1.0)
        self._hc = np.arange(1.0, hc + 1.0)
        scale = 1.0 if s.q_rate_hz is None else self.dt * s.q_rate_hz
        u2 = self.unit**2
        qa = np.concatenate(
            [np.full(2 * hr, s.q_respiratory), [s.q_offset], np.full(2 * hc, s.q_cardiac)]
        )
        q_wr = s.q_omega if s.q_omega_respiratory is None else s.q_omega_respiratory
        self._q = np.concatenate([np.tile(qa / u2, d), [q_wr, s.q_omega, 0.0, 0.0]]) * scale
        if s.q_omega_cardiac_per_second is not None:
            self._q[self.iwc] = s.q_omega_cardiac_per_second * self.dt
        self._r = s.r / u2
        c0 = np.arange(d)[:, None] * k + 2 * hr + 1
        self._id, self._ie = (c0 + np.arange(hc)).ravel(), (c0 + hc + np.arange(hc)).ravel()
        qp = s.q_phase_cardiac_per_second
        self._q_phase = 0.0 if qp is None else qp * self.dt
        p0 = np.full(k, s.p0_coefficient / u2)
        p0[2 * hr] = s.p0_offset / u2
        self._p0 = np.concatenate(
            [np.tile(p0, d), [s.p0_omega_respiratory, s.p0_omega_cardiac, 0.0, 0.0]]
        )
        self._w_lo, self._w_hi = (_TWO_PI * f for f in s.omega_limits_hz)
        self.x = np.zeros(self.nx)
        self.P = np.zeros((self.nx, self.nx))
        self._Pdiag = np.einsum("ii->i", self.P)  # writable view
        self._coef = self.x[: d * k].reshape(d, k)
        self._H = np.zeros((d, self.nx))
        self._Hblk = np.einsum("aaj->aj", self._H[:, : d * k].reshape(d, d, k))
        self.nis = math.nan
        self._gate = math.inf if s.gate_probability is None else chi2.ppf(s.gate_probability, d)
        self._max_reject, self._rejected = max(1, round(s.gate_seconds / self.dt)), 0
        self._c_lo, self._c_hi = (_TWO_PI * f for f in s.cardiac_band_hz)
        self._r_lo, self._r_hi = (_TWO_PI * f for f in s.respiratory_band_hz)
        if s.init_seconds is not None:
            n = max(round(s.init_seconds / self.dt), 2 * k)
            self._window = FitWindow(n, d)
        self._rest, self._hph, self._fit_omega = None, None, math.nan
        if s.adaptive_r or s.residual_order:
            self._rest = NonPeriodic(d, self.dt, self._r, s.adaptive_r, s.residual_order,
                                     s.residual_forgetting, self.unit, s.cardiac_band_hz[0],
                                     self.counts)

    def _start(self, z: np.ndarray) -> None:
        """Richa's start at the first sample, or collect Yuen's window and fit it."""
        s, hr = self.settings, self.settings.respiratory_harmonics
        if s.init_seconds is None:  # Richa: zeros, given frequencies; the offset at z
            self.x[:] = 0.0
            self.P[:] = 0.0
            self._Pdiag[:] = self._p0
            self._coef[:, 2 * hr] = z
            self.x[self.iwr] = _TWO_PI * s.respiratory_hz
            self.x[self.iwc] = _TWO_PI * s.cardiac_hz
            self.ready = True
            return
        self._window.push(z)
        if self._window.full:
            self.ready = self._fit()

    def _lost(self) -> bool:
        """ω̂_c or ω̂_r outside the band its initialisation searches, or ω̂_c outside
        ``rate_band`` around the last fit's rate (lock lost)."""
        wr, wc = self.x[self.iwr], self.x[self.iwc]
        inside = self._c_lo <= wc <= self._c_hi and self._r_lo <= wr <= self._r_hi
        b = self.settings.rate_band
        if b is not None:
            inside = inside and self._fit_omega / b <= wc <= self._fit_omega * b
        return not inside and self._window.full

    def _fit(self) -> bool:
        """Fit the window (oldest first) as Yuen; False (state untouched) if < 80 % finite."""
        s, hr = self.settings, self.settings.respiratory_harmonics
        if not self._window.usable():
            return False
        self.x[:] = 0.0
        self.P[:] = 0.0
        self._Pdiag[:] = self._p0
        window = self._window.oldest_first()
        wc, c, r, th, wr, a, b = initial_dual_state(
            window,
            self.dt,
            s.cardiac_harmonics,
            s.cardiac_band_hz,
            hr,
            s.respiratory_band_hz,
            _TWO_PI * s.respiratory_hz if s.respiratory_known else None,
        )
        coef = self._coef  # θ_r = θ_c = 0 at the newest sample: r sin(hθ_c + φ) → d, e
        coef[:, :hr], coef[:, hr : 2 * hr], coef[:, 2 * hr] = a, b, c
        coef[:, 2 * hr + 1 : 2 * hr + 1 + r.shape[1]] = r * np.cos(th)
        coef[:, 2 * hr + 1 + r.shape[1] :] = r * np.sin(th)
        self.x[self.iwr], self.x[self.iwc] = wr, wc
        self._fit_omega = wc
        if s.fit_beats:
            self._refit_recent(window)
        if s.p0_respiratory_from_fit:
            self._covariance_from_fit(window)
        self._rejected = 0
        if self._rest is not None:
            self._rest.restart()
        return True

    def _refit_recent(self, window: np.ndarray) -> None:
        """Offset and cardiac coefficients again from the window's last ``fit_beats`` beats,
        its respiratory fit removed (as the ``ekf``'s ``fit_beats``)."""
        hr, wc = self.settings.respiratory_harmonics, self.x[self.iwc]
        n = round(self.settings.fit_beats * _TWO_PI / (wc * self.dt))
        n = max(2 * (2 * self._hc.size + 1), min(len(window), n))
        lag = -np.arange(n - 1.0, -1.0, -1.0) * self.dt
        phi = self._basis(lag * self.x[self.iwr], lag * wc)
        resp = phi[:, : 2 * hr] @ self._coef[:, : 2 * hr].T
        c, a, b = fit_harmonics(window[-n:] - resp, self.dt, wc, self._hc.size)
        self._coef[:, 2 * hr], self._coef[:, 2 * hr + 1 :] = c, np.hstack([a, b])

    def _covariance_from_fit(self, window: np.ndarray) -> None:
        """Respiratory coefficients and offset (and with ``p0_cardiac_from_fit`` the cardiac
        ones) start at the least-squares covariance of the window fit, s_a²·[(ΦᵀΦ)⁻¹]; s_a² the
        residual variance per axis (its long-run variance with ``p0_cardiac_from_fit``)."""
        s, n = self.settings, len(window)
        lag = np.arange(n - 1.0, -1.0, -1.0) * -self.dt
        ok = np.isfinite(window).all(axis=1)
        phi = self._basis(lag[ok] * self.x[self.iwr], lag[ok] * self.x[self.iwc])
        res = window[ok] - phi @ self._coef.T
        if s.p0_cardiac_from_fit:
            s2, m = np.maximum(long_run_variance(res), self._r), self.k
        else:
            s2 = np.sum(res**2, axis=0) / max(int(ok.sum()) - self.k, 1)
            m = 2 * s.respiratory_harmonics + 1
        cov = np.linalg.pinv(phi.T @ phi)[:m, :m]
        for ax in range(self.d):
            self.P[ax * self.k : ax * self.k + m, ax * self.k : ax * self.k + m] = s2[ax] * cov

    def _basis(self, th_r: np.ndarray, th_c: np.ndarray) -> np.ndarray:
        """[sin hθ_r, cos hθ_r, 1, sin hθ_c, cos hθ_c] for phases of shape (K,) → (K, k)."""
        hr, hc = self._hr.size, self._hc.size
        out = np.empty((th_r.shape[0], self.k))
        pr = np.multiply.outer(th_r, self._hr)
        pc = np.multiply.outer(th_c, self._hc)
        np.sin(pr, out=out[:, :hr])
        np.cos(pr, out=out[:, hr : 2 * hr])
        out[:, 2 * hr] = 1.0
        np.sin(pc, out=out[:, 2 * hr + 1 : 2 * hr + 1 + hc])
        np.cos(pc, out=out[:, 2 * hr + 1 + hc :])
        return out

    def _update(self, z: np.ndarray) -> None:
        s = self.settings
        if self._rest is not None:
            self._rest.push(z)
        if not self.ready:
            self._start(z)
            self._follow(learn=False)
            return
        if s.init_seconds is not None:
            self._window.push(z)
        self._time_update()
        accepted = self._correct(z)
        if accepted:
            if s.init_seconds is not None and self._lost() and self._fit():
                self.counts["lock_refit"] += 1
        elif self._rest is not None:
            self._rest.reject()
        self._follow(learn=accepted)

    def _follow(self, learn: bool) -> None:
        """The non-periodic part from the current state (:mod:`predictors.nonperiodic`)."""
        if self._rest is not None and self.ready:
            self._rest.follow(self._model, self.x[self.iwc], self._hph, learn)

    def _correct(self, z: np.ndarray) -> bool:
        """The EKF correction (eqs. 3–5) with sample z; False if gated out or S is not SPD."""
        s = self.settings
        x, P, H, hr = self.x, self.P, self._H, s.respiratory_harmonics
        phi = self._basis(x[self.itr : self.itr + 1], x[self.itc : self.itc + 1])[0]
        self._Hblk[:] = phi
        coef = self._coef
        # ∂y/∂θ_r = Σ h (a_h cos hθ_r − b_h sin hθ_r); likewise for θ_c
        sr, cr = phi[:hr], phi[hr : 2 * hr]
        sc, cc = phi[2 * hr + 1 : 2 * hr + 1 + len(self._hc)], phi[2 * hr + 1 + len(self._hc) :]
        a, b = coef[:, :hr], coef[:, hr : 2 * hr]
        dd, e = (
            coef[:, 2 * hr + 1 : 2 * hr + 1 + len(self._hc)],
            coef[:, 2 * hr + 1 + len(self._hc) :],
        )
        H[:, self.itr] = (a * cr - b * sr) @ self._hr
        H[:, self.itc] = (dd * cc - e * sc) @ self._hc
        nu = z - coef @ phi
        PHt = P @ H.T
        S = H @ PHt
        self._hph = S.diagonal().copy()
        S.flat[:: self.d + 1] += self._r if self._rest is None else self._rest.r
        Sinv = spd_inverse(S)
        if Sinv is None:
            self.counts["ekf_reinit"] += 1
            self.ready = False
            if s.init_seconds is not None:
                self._window.clear()
            return False
        Sinv_nu = Sinv @ nu
        self.nis = float(nu @ Sinv_nu)
        if self.nis > self._gate and self._rejected < self._max_reject:
            self.counts["innovation_rejected"] += 1
            self._rejected += 1
            return False
        self._rejected = 0
        x += PHt @ Sinv_nu
        P -= (PHt @ Sinv) @ PHt.T
        P += P.T
        P *= 0.5
        wrap_phase(x[self.itr :])
        for i in (self.iwr, self.iwc):
            if not self._w_lo <= x[i] <= self._w_hi:
                self.counts["omega_clamped"] += 1
                x[i] = min(max(x[i], self._w_lo), self._w_hi) if math.isfinite(x[i]) else 1.0
        return True

    def _time_update(self) -> None:
        x, P, dt = self.x, self.P, self.dt
        x[self.itr] += dt * x[self.iwr]
        x[self.itc] += dt * x[self.iwc]
        wrap_phase(x[self.itr :])
        for it, iw in ((self.itr, self.iwr), (self.itc, self.iwc)):  # F P Fᵀ, F = I + Δt e_θ e_ωᵀ
            P[it, :] += dt * P[iw, :]
            P[:, it] += dt * P[:, iw]
        self._Pdiag += self._q
        if self._q_phase:  # phase walk of each cardiac harmonic: G q_φ Gᵀ, G = (−e_h, d_h)
            d, e = x[self._id], x[self._ie]
            P[self._id, self._id] += self._q_phase * e * e
            P[self._ie, self._ie] += self._q_phase * d * d
            P[self._id, self._ie] -= self._q_phase * d * e
            P[self._ie, self._id] -= self._q_phase * d * e

    def _missing(self) -> None:
        if self.ready:
            if self.settings.init_seconds is not None:
                self._window.push(np.full(self.d, np.nan))
            self._time_update()
        elif self.settings.init_seconds is not None:
            self._start(np.full(self.d, np.nan))
        if self._rest is not None:
            self._rest.push(np.nan)
            self._follow(learn=False)

    def _model(self, k: np.ndarray) -> np.ndarray:
        """Eq. (1) k samples ahead of the state (any k, past ones negative), (len(k), d)."""
        k, x = np.asarray(k, dtype=float), self.x
        phi = self._basis(
            x[self.itr] + k * x[self.iwr] * self.dt, x[self.itc] + k * x[self.iwc] * self.dt
        )
        return phi @ self._coef.T

    def _predict(self, steps: int) -> np.ndarray:
        if self._rest is None:
            return self._model(np.arange(1.0, steps + 1.0))
        y = self._model(np.arange(0.0, steps + 1.0))  # ŷ_{n+k|n} + ê_{n+k|n}
        return y[1:] + self._rest.forecast(np.diff(y, axis=0))

    @property
    def heart_rate_hz(self) -> float:
        """Cardiac frequency estimate ω̂_c/2π [Hz]; NaN before the first sample."""
        return float(self.x[self.iwc] / _TWO_PI) if self.ready else math.nan

    @property
    def frequencies_hz(self) -> tuple[float, float]:
        """(respiratory, cardiac) frequency estimates [Hz]."""
        return float(self.x[self.iwr] / _TWO_PI), float(self.x[self.iwc] / _TWO_PI)
