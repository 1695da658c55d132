"""Weighted-frequency Fourier linear combiner, WFLC (Riviere et al. 1998; Yuen et al. 2009, §4.2).

Model with accumulated phase ψ_k = Σ_{t≤k} ω₀,t (ω₀ in rad/sample), per axis a::

    x_k = [sin ψ_k, …, sin mψ_k, cos ψ_k, …, cos mψ_k],   ŷ_{a,k} = w_aᵀ x_k + w_{a,b},
    ε_{a,k} = z_{a,k} − ŷ_{a,k},
    ω₀ ← ω₀ + 2μ₀ Σ_a ε_{a,k} Σ_{r=1}^{m} r (w_{a,r} cos rψ_k − w_{a,m+r} sin rψ_k),
    w_a ← w_a + 2μ₁ ε_{a,k} x_k,   w_{a,b} ← w_{a,b} + 2μ_b ε_{a,k}.

One frequency is shared by the axes (their frequency gradients add).  Forecast k
steps: ψ + kω₀ in the model.  Initialised like the EKF (Yuen): FFT + least squares
on the first ``init_seconds`` (ψ = 0 at the newest sample); until then the forecast
holds the newest sample.  A missing sample advances ψ and ψ_b only.

Parameters (Yuen et al. 2009): m = 8, μ₀ = 7e-6, μ₁ = 0.03, tuned at 28 Hz on data in
mm.  μ₀ multiplies ε·w (mm²), so it is stored in SI as 7e-6 rad/mm² = 7 rad/m² per
sample, and converted to data units by unit².  Rate: at another sample rate the same
gains adapt faster per second (more updates, and ω₀ in rad/sample), so with
``gain_rate_hz`` = 28 they are rescaled to adapt as fast per second as at 28 Hz:
μ₀ · (Δt·28)², μ₁ · (Δt·28).  μ_b is not rescaled: the offset weight is what follows
breathing (time constant 1/(2μ_b) samples).

Phase-locked loop (ours; ``loop="pll"``).  With physiological heart-rate variability (RSA
swings the rate by several bpm within one 4–6 s breath) the μ₀ gradient is too slow to
follow the rate; ψ and ω₀ are instead driven by a normalised phase detector, a second-order
(type-2) phase-locked loop (Gardner, *Phaselock Techniques*, 3rd ed., 2005, ch. 2–4; the PLL
view of the WFLC's frequency adaptation)::

    (P1) δ_k = Σ_a ε_{a,k} g_{a,k} / P_k,  g_a = Σ_{r≤j} r (w_{a,r} cos rψ − w_{a,m+r} sin rψ),
         P = ½ Σ_a Σ_{r≤j} r² (w_{a,r}² + w_{a,m+r}²)   (cycle mean of Σ_a g_a²),
    (P2) ψ ← ψ + 2ζω_nΔt · clip(δ, ±δ_max),
    (P3) ω₀ ← ω₀ + (ω_nΔt)² · clip(δ, ±δ_max),   then clamped to the heart band (counted).

δ is the least-squares phase error (z ≈ ŷ(ψ + δ) linearised), dimensionless, so the loop
is independent of the data unit and, with ω_n in Hz, of the sample rate.  j =
``pll_harmonics`` = 1: the fundamental only, as ``frequency_harmonics`` for μ₀.  ω_n =
2π·0.5 Hz, ζ = 1/√2 (a slower loop lags the RSA, a faster one follows beat-to-beat waveform
changes).  δ_max = 1 rad bounds the step an echo outlier can make.  A rate step is a phase
ramp, which a type-2 loop follows with no steady-state error, so ω̂ cannot run away.

Respiration (ours; Richa et al. 2010 eq. 1, the model the EKF also carries):
``breathing_harmonics`` = H_b = 2 terms Σ_h a_{a,h} sin hψ_b + b_{a,h} cos hψ_b with their
own accumulated phase ψ_b, initialised with the heart series (FFT in the breathing band,
joint least squares, :func:`rhmpc.predictors.fourier_init.initial_dual_state`), adapted by LMS
with μ₁ and a slow loop (P1–P3 on ψ_b, ω_n = 2π·0.02 Hz) clamped to
``breathing_band_hz``.  Without it the offset weight follows breathing with a lag of
1/(2μ_b) samples; with breathing modelled the offset only follows drift: μ_b = 0.01
(Riviere's 0.03 absorbs heartbeat error).

Motion that is not periodic (``adaptive``, the default parameter set: ``pll`` sized to the
heart rate, so that the weights and the loop do not chase each beat's deviations):

* ``loop_ratio`` = 0.3: ω_n = 0.3 ω̂₀;
* ``weight_beats`` = 2: μ₁ = ω̂₀Δt/(8π), the weights' time constant two beats, over which
  beat-to-beat deviations average out;
* ``residual_order`` = 16: the AR model of the residual of :mod:`rhmpc.predictors.nonperiodic`
  (without R: the WFLC has none) adds to the forecast, which starts from the newest sample.

Each part's effect is measured by ``benchmarks/invivo_regime.py``
(``docs/validation/predictors.md``).

``loop="gradient"`` with ``breathing_harmonics=0`` is the gradient update: the μ₀
gradient on the fundamental plus the phase-locked correction ω₀ += κΔφ (Δφ the rotation
of the fundamental weights, κ = 0.01 per sample at 28 Hz); with ``phase_gain=0,
frequency_harmonics=8, mu_bias=0.03`` it is Riviere's WFLC.  ``offset_natural_hz`` (default
off) replaces the offset weight by a second-order tracker b ← b + v + k₁ε, v ← v + k₂ε.  Cost
per update: O((m + H_b)·d).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rhmpc.predictors.base import PredictorSettings
from rhmpc.predictors.fourier_init import initial_dual_state, initial_fourier_state
from rhmpc.predictors.nonperiodic import FourierPredictor, NonPeriodic

__all__ = ["WFLC", "WFLCSettings"]


def _output_slope(sin_w: np.ndarray, cos_w: np.ndarray, sn: np.ndarray, cs: np.ndarray,
                  r: np.ndarray) -> np.ndarray:
    """∂ŷ_a/∂ψ = Σ_r r (a_{a,r} cos rψ − b_{a,r} sin rψ) per axis, (d,): the Fourier series'
    slope in its phase (sin weights a, cos weights b, harmonic numbers r)."""
    return (sin_w * cs - cos_w * sn) @ r


def _phase_detector(eps: np.ndarray, sin_w: np.ndarray, cos_w: np.ndarray, sn: np.ndarray,
                    cs: np.ndarray, r: np.ndarray, limit: float) -> float | None:
    """Normalised least-squares phase error δ = Σ_a ε_a g_a / P, clipped to ±``limit`` [rad]
    (module docstring, eq. P1), with g the slope of :func:`_output_slope` and P its cycle-mean
    power ½ Σ_a Σ_r r² (a² + b²); ``None`` while the series has no power."""
    g = _output_slope(sin_w, cos_w, sn, cs, r)
    power = 0.5 * float(np.sum((sin_w * sin_w + cos_w * cos_w) @ (r * r)))
    if not power > 0.0 or not math.isfinite(power):
        return None
    return min(max(float(eps @ g) / power, -limit), limit)


@dataclass(frozen=True)
class WFLCSettings(PredictorSettings):
    """WFLC settings (m, μ₀, μ₁: Yuen et al. 2009; loop, respiration, μ_b: ours).

    Attributes
    ----------
    harmonics : int
        m [-].
    mu0 : float
        Frequency adaptation gain μ₀ [rad per sample per m²] (7e-6 rad/mm²).
    mu1 : float
        Weight adaptation gain μ₁ [-].
    mu_bias : float
        Offset adaptation gain μ_b [-] (Riviere: 0.03; ours 0.01, see above).
    init_seconds : float
        FFT + least-squares initialisation window [s].
    band_hz : tuple of float
        Heart-rate band searched by the FFT [Hz].
    omega_limits_hz : tuple of float
        ω₀ is clamped to this range [Hz] (36–210 beats/min).
    gain_rate_hz : float or None
        Rate μ₀, μ₁, κ were tuned at [Hz] (Yuen: 28); ``None``: per own sample.
    phase_gain : float
        κ, gain of the phase-locked frequency correction [-] (``loop="gradient"``; 0 =
        Riviere's WFLC).
    frequency_harmonics : int
        Harmonics whose phase errors drive the μ₀ gradient [-] (Riviere: all m; ours: 1).
    loop : str
        ``"pll"`` (P1–P3, ours) or ``"gradient"`` (μ₀ gradient + κ correction).
    pll_natural_hz : float
        Natural frequency ω_n/2π of the heart-phase loop [Hz].
    pll_damping : float
        Damping ratio ζ of the loops [-].
    pll_harmonics : int
        Harmonics j in the phase detector (P1) [-].
    pll_max_phase_error : float
        δ_max, clip of the phase detector output [rad].
    offset_natural_hz : float or None
        Natural frequency of the second-order offset tracker [Hz]; ``None``: Riviere's
        first-order offset weight with μ_b.
    offset_damping : float
        Damping ratio of that tracker [-].
    breathing_harmonics : int
        H_b, respiratory harmonics [-]; 0 = no respiratory series (Riviere/Yuen).
    breathing_band_hz : tuple of float
        Respiratory band [Hz]: FFT search and clamp of ω_b.
    breathing_natural_hz : float
        Natural frequency of the respiratory-phase loop [Hz].
    loop_ratio : float or None
        Heart-phase loop natural frequency as a fraction of the heart rate, ω_n = ratio·ω̂₀
        (``loop="pll"``); ``None``: ``pll_natural_hz``.
    weight_beats : float or None
        μ₁ such that the weights' LMS time constant 1/(2μ₁) lasts this many beats at ω̂₀:
        μ₁ = ω̂₀Δt/(4π·beats); ``None``: ``mu1``.
    residual_order : int
        p of the autoregression of the residual (:mod:`rhmpc.predictors.residual`); 0: none.
    residual_forgetting : float
        λ of its RLS [-].
    unit : float or None
        Metres per data unit; ``None``: inferred from the data (see ``rhmpc.predictors.base``).
    """

    harmonics: int = 8
    mu0: float = 7e-6 / 1e-6
    mu1: float = 0.03
    mu_bias: float = 0.01
    init_seconds: float = 10.0
    band_hz: tuple[float, float] = (0.6, 3.0)
    omega_limits_hz: tuple[float, float] = (0.6, 3.5)
    gain_rate_hz: float | None = 28.0
    phase_gain: float = 0.01
    frequency_harmonics: int = 1
    loop: str = "pll"
    pll_natural_hz: float = 0.5
    pll_damping: float = 1.0 / math.sqrt(2.0)
    pll_harmonics: int = 1
    pll_max_phase_error: float = 1.0
    offset_natural_hz: float | None = None
    offset_damping: float = 1.0
    breathing_harmonics: int = 2
    breathing_band_hz: tuple[float, float] = (0.08, 0.5)
    breathing_natural_hz: float = 0.02
    loop_ratio: float | None = None
    weight_beats: float | None = None
    residual_order: int = 0
    residual_forgetting: float = 0.999
    unit: float | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.harmonics) != self.harmonics or self.harmonics < 1:
            raise ValueError(f"harmonics must be a positive integer, got {self.harmonics!r}")
        if not 1 <= self.frequency_harmonics <= self.harmonics:
            raise ValueError("frequency_harmonics must be in 1..harmonics")
        if self.loop not in ("pll", "gradient"):
            raise ValueError(f"loop must be 'pll' or 'gradient', got {self.loop!r}")
        if not 1 <= self.pll_harmonics <= self.harmonics:
            raise ValueError("pll_harmonics must be in 1..harmonics")
        for name in ("pll_natural_hz", "pll_damping", "pll_max_phase_error"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("mu0", "mu1", "mu_bias", "phase_gain"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if self.gain_rate_hz is not None and not self.gain_rate_hz > 0.0:
            raise ValueError(f"gain_rate_hz must be > 0 or None, got {self.gain_rate_hz!r}")
        for name in ("init_seconds",):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("loop_ratio", "weight_beats"):
            v = getattr(self, name)
            if v is not None and not v > 0.0:
                raise ValueError(f"{name} must be > 0 or None, got {v!r}")
        if int(self.residual_order) != self.residual_order or self.residual_order < 0:
            raise ValueError(f"residual_order must be an integer >= 0, got {self.residual_order!r}")

    @classmethod
    def yuen2009(cls, **overrides) -> WFLCSettings:
        """Yuen et al. 2009's WFLC (the 28 Hz studies).

        The μ₀ gradient frequency update with the κ phase-locked correction
        (``loop="gradient"``), no respiratory series (Yuen's 1-D mitral signal has no
        breathing) and Riviere's offset gain μ_b = 0.03; m, μ₀, μ₁ are Yuen's.  At 28 Hz and
        σ_R = 1.3 mm it gives 0.85 mm at ΔHR = 0 in the hr-step study, where the PLL's
        fixed 0.5 Hz bandwidth passes the phase detector's noise (2.16 mm).  The default
        (``loop="pll"`` with breathing) is for 3-D motion with breathing.
        """
        base = {"loop": "gradient", "breathing_harmonics": 0, "mu_bias": 0.03}
        return cls(**{**base, **overrides})


#: Named settings for ``make_predictor("wflc", dt, params=...)``: ``yuen2009`` (Yuen's
#: algorithm), ``pll`` (the phase-locked loop at a fixed 0.5 Hz with respiration) and
#: ``adaptive`` (the default: ``pll`` with the loop and the weights sized to the heart rate and
#: the residual's AR(16); module docstring, "Motion that is not periodic").
PARAMETER_SETS: dict[str, WFLCSettings] = {
    "pll": WFLCSettings(),
    "yuen2009": WFLCSettings.yuen2009(),
    "adaptive": WFLCSettings(loop_ratio=0.3, weight_beats=2.0, residual_order=16),
}


class WFLC(FourierPredictor):
    """Weighted-frequency Fourier linear combiner with accumulated phase."""

    PRESETS = PARAMETER_SETS
    Settings = WFLCSettings

    def _allocate(self, d: int) -> None:
        s = self.settings
        m = s.harmonics
        self.n_init = max(round(s.init_seconds / self.dt), 4 * m + 2)
        self._window = np.full((self.n_init, d), np.nan)
        self._filled = 0
        self._r = np.arange(1.0, m + 1.0)
        self.w = np.zeros((d, 2 * m))  # [sin weights, cos weights] per axis
        self.bias = np.zeros(d)
        hb = s.breathing_harmonics
        self._rb = np.arange(1.0, hb + 1.0)
        self.wb = np.zeros((d, 2 * hb))  # breathing [sin, cos] weights per axis
        self.omega_b = 0.0  # rad/sample
        self.psi_b = 0.0
        self._blo, self._bhi = (2 * math.pi * f * self.dt for f in s.breathing_band_hz)
        wnb = 2 * math.pi * s.breathing_natural_hz * self.dt
        self._kpb, self._kib = 2 * s.pll_damping * wnb, wnb * wnb
        self.bias_rate = np.zeros(d)  # offset velocity [data units per sample]
        self.omega0 = 0.0  # rad/sample
        self.psi = 0.0
        rate = 1.0 if s.gain_rate_hz is None else self.dt * s.gain_rate_hz
        self._mu0 = s.mu0 * self.unit**2 * rate**2
        self._mu1 = s.mu1 * rate
        self._kappa = s.phase_gain * rate
        self._lo, self._hi = (2 * math.pi * f * self.dt for f in s.omega_limits_hz)
        wn = 2 * math.pi * s.pll_natural_hz * self.dt  # ω_n [rad/sample]
        self._kp, self._ki = 2 * s.pll_damping * wn, wn * wn
        self.phase_error = 0.0  # δ of the last update [rad]
        self._rest = None
        if s.residual_order:
            self._rest = NonPeriodic(d, self.dt, 0.0, False, s.residual_order,
                                     s.residual_forgetting, self.unit, s.band_hz[0], self.counts)
        if s.offset_natural_hz is None:
            self._kb1, self._kb2 = 2 * s.mu_bias, 0.0
        else:
            wb = 2 * math.pi * s.offset_natural_hz * self.dt
            self._kb1, self._kb2 = 2 * s.offset_damping * wb, wb * wb

    @property
    def omega(self) -> float:
        """ω̂ [rad/s]."""
        return self.omega0 / self.dt

    @property
    def heart_rate_hz(self) -> float:
        """ω̂/2π [Hz]; NaN until initialised."""
        return self.omega0 / (2 * math.pi * self.dt) if self.ready else math.nan

    def _initialise(self) -> None:
        order = np.roll(np.arange(self.n_init), -(self._filled % self.n_init))
        s = self.settings
        if s.breathing_harmonics:
            omega, c, r, th, omega_b, a, b = initial_dual_state(
                self._window[order],
                self.dt,
                s.harmonics,
                s.band_hz,
                s.breathing_harmonics,
                s.breathing_band_hz,
            )
            self.wb[:] = np.hstack([a, b])
            self.omega_b, self.psi_b = omega_b * self.dt, 0.0
        else:
            omega, c, r, th = initial_fourier_state(
                self._window[order], self.dt, self.settings.harmonics, self.settings.band_hz
            )
        m = self.settings.harmonics
        self.w[:, :m] = r * np.cos(th)  # a_i: r sin(iψ + θ) = a sin iψ + b cos iψ
        self.w[:, m:] = r * np.sin(th)
        self.bias[:] = c
        self.omega0 = omega * self.dt
        self.psi = 0.0
        self.ready = True

    def _update(self, z: np.ndarray) -> None:
        if self._rest is not None:
            self._rest.push(z)
        if not self.ready:
            self._window[self._filled % self.n_init] = z
            self._filled += 1
            if self._filled >= self.n_init:
                self._initialise()
            self._follow(learn=False)
            return
        self._adapt(z)
        self._follow(learn=True)

    def _rate(self) -> float:
        return self.omega0 / self.dt

    def _mu1_now(self) -> float:
        """μ₁: fixed, or ``weight_beats`` beats of LMS memory at ω̂₀."""
        beats = self.settings.weight_beats
        return self._mu1 if beats is None else self.omega0 / (4 * math.pi * beats)

    def _adapt(self, z: np.ndarray) -> None:
        """One WFLC step with sample z (module docstring)."""
        s, m = self.settings, self.settings.harmonics
        mu1 = self._mu1_now()
        self.psi = math.remainder(self.psi + self.omega0, 2 * math.pi)
        self.bias += self.bias_rate
        ph = self._r * self.psi
        sn, cs = np.sin(ph), np.cos(ph)
        ws, wc = self.w[:, :m], self.w[:, m:]
        eps = z - ws @ sn - wc @ cs - self.bias
        hb = self._rb.size
        if hb:
            self.psi_b = math.remainder(self.psi_b + self.omega_b, 2 * math.pi)
            phb = self._rb * self.psi_b
            xb = np.concatenate([np.sin(phb), np.cos(phb)])
            eps -= self.wb @ xb
            if s.loop == "pll":
                self._breathing_pll(eps, xb)
            self.wb += (2 * mu1) * np.multiply.outer(eps, xb)
        if s.loop == "pll":
            self._pll(eps, sn, cs)
            ws += (2 * mu1) * np.multiply.outer(eps, sn)
            wc += (2 * mu1) * np.multiply.outer(eps, cs)
            self.bias += self._kb1 * eps
            self.bias_rate += self._kb2 * eps
            return
        j = s.frequency_harmonics
        grad = float(eps @ _output_slope(ws[:, :j], wc[:, :j], sn[:j], cs[:j], self._r[:j]))
        w1 = self.w[:, [0, m]].copy()  # fundamental weights (sin, cos) before adaptation
        w0 = self.omega0 + 2 * self._mu0 * grad
        if not self._lo <= w0 <= self._hi:
            self.counts["omega_clamped"] += 1
            w0 = min(max(w0, self._lo), self._hi) if math.isfinite(w0) else self.omega0
        self.omega0 = w0
        ws += (2 * mu1) * np.multiply.outer(eps, sn)
        wc += (2 * mu1) * np.multiply.outer(eps, cs)
        self.bias += (2 * s.mu_bias) * eps
        if self._kappa:  # phase-locked correction: the rotation the weights made, Δφ
            w2 = self.w[:, [0, m]]
            cross = float(np.sum(w1[:, 0] * w2[:, 1] - w1[:, 1] * w2[:, 0]))
            dphi = math.atan2(cross, float(np.sum(w1 * w2)))
            self.omega0 = min(max(self.omega0 + self._kappa * dphi, self._lo), self._hi)

    def _pll(self, eps: np.ndarray, sn: np.ndarray, cs: np.ndarray) -> None:
        """Second-order phase-locked loop on ψ and ω₀ (module docstring, eqs. P1–P3)."""
        j = self.settings.pll_harmonics
        ws, wc = self.w[:, :j], self.w[:, self.settings.harmonics :][:, :j]
        delta = _phase_detector(eps, ws, wc, sn[:j], cs[:j], self._r[:j],
                                self.settings.pll_max_phase_error)
        if delta is None:
            return
        self.phase_error = delta
        kp, ki = self._kp, self._ki
        if self.settings.loop_ratio is not None:  # ω_n = ratio·ω̂₀ [rad/sample]
            wn = self.settings.loop_ratio * self.omega0
            kp, ki = 2 * self.settings.pll_damping * wn, wn * wn
        self.psi = math.remainder(self.psi + kp * delta, 2 * math.pi)
        w0 = self.omega0 + ki * delta
        if not self._lo <= w0 <= self._hi:
            self.counts["omega_clamped"] += 1
            w0 = min(max(w0, self._lo), self._hi)
        self.omega0 = w0

    def _breathing_pll(self, eps: np.ndarray, xb: np.ndarray) -> None:
        """The loop of :meth:`_pll` on the respiratory phase ψ_b and rate ω_b."""
        hb = self._rb.size
        delta = _phase_detector(eps, self.wb[:, :hb], self.wb[:, hb:], xb[:hb], xb[hb:],
                                self._rb, self.settings.pll_max_phase_error)
        if delta is None:
            return
        self.psi_b = math.remainder(self.psi_b + self._kpb * delta, 2 * math.pi)
        w = self.omega_b + self._kib * delta
        if not self._blo <= w <= self._bhi:
            self.counts["breathing_clamped"] += 1
            w = min(max(w, self._blo), self._bhi)
        self.omega_b = w

    def _missing(self) -> None:
        if self.ready:
            self.psi = math.remainder(self.psi + self.omega0, 2 * math.pi)
            self.bias += self.bias_rate
            if self._rb.size:
                self.psi_b = math.remainder(self.psi_b + self.omega_b, 2 * math.pi)
        else:
            self._window[self._filled % self.n_init] = np.nan
            self._filled += 1
        self._rest_missing()

    def _model(self, k: np.ndarray) -> np.ndarray:
        """ŷ k samples ahead of the newest (any k, past ones negative), (len(k), d)."""
        m, k = self.settings.harmonics, np.asarray(k, dtype=float)
        ph = np.multiply.outer(self.psi + self.omega0 * k, self._r)
        trend = self.bias + np.multiply.outer(k, self.bias_rate)
        out = np.sin(ph) @ self.w[:, :m].T + np.cos(ph) @ self.w[:, m:].T + trend
        hb = self._rb.size
        if hb:
            phb = np.multiply.outer(self.psi_b + self.omega_b * k, self._rb)
            out += np.sin(phb) @ self.wb[:, :hb].T + np.cos(phb) @ self.wb[:, hb:].T
        return out

