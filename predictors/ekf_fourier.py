"""Quasiperiodic time-varying Fourier-series EKF (Yuen et al. 2008, §III-A; Tuna 2013, §VIII-C).

Model, per axis a (eq. 2), one heart rate ω shared by all axes:

    y_a(t) = c_a(t) + Σ_{i=1}^{m} r_{a,i}(t) sin θ_{a,i}(t),   θ_{a,i} = i ∫ω dt + φ_{a,i}(t),

state x = [c_a, r_{a,1..m} (for each a), ω, θ_{a,1..m} (for each a)], random walks
on c, r, ω, φ.

Breathing (``breathing_harmonics`` = H_b > 0; an extension for 3-D motion with
breathing, Richa et al. 2010 eq. 1): each axis adds Σ_{h=1}^{H_b} a_{a,h} sin hθ_b +
b_{a,h} cos hθ_b with one respiratory rate ω_b and accumulated phase θ_b (θ_b += ω_bΔt)
shared by the axes; a, b, ω_b are random walks with Richa's process variances, appended
to the state as [a_{a,1..H_b}, b_{a,1..H_b} (for each a), ω_b, θ_b].

Discrete model x⁺ = F x + μ, F = I except ∂θ_{a,i}/∂ω = iΔt,
μ ~ N(0, Q), z = h(x) + ν, ν ~ N(0, σ_R² I).  EKF recursion (Yuen, §III-A):

    P⁻ = F P Fᵀ + Q,   S = H P⁻ Hᵀ + σ_R² I,   K = P⁻ Hᵀ S⁻¹,
    x̂ = F x̂ + K (z − h(F x̂)),   P = (I − K H) P⁻,

with H = ∂h/∂x: ∂y_a/∂c_a = 1, ∂y_a/∂r_{a,i} = sin θ_{a,i}, ∂y_a/∂θ_{a,i} = r_{a,i} cos θ_{a,i}.

Initialisation (Yuen): the first ``init_seconds`` of samples give ω̂₀ by FFT and
c, r, θ by least squares (:mod:`rhmpc.predictors.fourier_init`; with breathing, ω̂_b is found
first and its fit removed, so ω̂₀ comes from the heart band only); then
P(T|T) = diag[σ_R²/N, σ₁², σ₁²/2², …, σ₁²/m², σ_ω², σ_θ², …].  Until then the
forecast holds the newest sample.  Forecast k steps: θ + iω̂kΔt in eq. (2).

Outliers: a sample whose normalised innovation squared νᵀS⁻¹ν exceeds the χ²_d quantile
``gate_probability`` is not used (the filter runs open-loop through it, counted
``innovation_rejected``); after ``gate_seconds`` of consecutive rejections samples are used
again, so a real change of the motion is followed.

Re-fit on lost lock (as :mod:`rhmpc.predictors.ekf_dual_fourier`): the last
``init_seconds`` of samples are kept (:class:`rhmpc.predictors.fourier_init.FitWindow`); when after
an update ω̂ ∉ 2π·``band_hz`` (the band the initialisation's FFT searches, 36–180 beats/min:
no heart the filter models) or ω̂ was clamped, state and covariance are re-fitted from that
window exactly as at the start (counted ``lock_refit``; needs ≥ 80 % finite samples); so is a
lock on a subharmonic (ω̂ ≈ ω/2, inside the band): the second harmonic's power Σ_a r_{a,2}²
exceeds the fundamental's, which the fit chose as the largest peak (judged once the window
holds only samples since the last fit).  A locked filter is unchanged.

Numerics: P is symmetrised each step; phases are wrapped to (−π, π]; ω̂ is clamped
to ``omega_limits_hz`` (counted ``omega_clamped``); a non-finite or non-positive
innovation covariance restarts the initialisation (counted ``ekf_reinit``).
Cost per update: O(n²) for the prediction (F is identity plus two columns) and
O(n² d) for the correction, n = d(2m + 1) + 1 + 2dH_b + 2 (48 for d = 3, m = 5, H_b = 2;
34 without breathing).

Motion that is not periodic (``adaptive``, the default parameter set: ``tuna2013-hrv`` with
these parts):

* ``adaptive_r``: R follows the long-run variance of the current state's residual over the
  last beat, minus the model's share H P⁻ Hᵀ (:mod:`rhmpc.predictors.nonperiodic`);
* ``residual_order`` = 16: an AR model of the residual, with the model's increments as input
  (:mod:`rhmpc.predictors.residual`), added to the forecast, which starts from the newest sample;
* ``p0_from_fit``: P(T|T) of c, r, θ and of the breathing coefficients is the least-squares
  covariance of the window fit, s²_lr·(AᵀA)⁻¹ (per axis; r and θ by first-order propagation
  from a, b), s²_lr the long-run variance of the fit's residual; σ_ω² stays Yuen's;
* ``fit_beats`` = 3: c, r, θ are fitted again on the window's last 3 beats (its breathing fit
  removed);
* ``rate_band`` = 1.5: ω̂ leaving [ω₀/1.5, 1.5 ω₀] of the fitted ω₀ is a lost lock too.

Each part's effect is measured by ``benchmarks/invivo_regime.py``
(``docs/validation/predictors.md``).

Units: Q, σ_R and σ₁² are given in SI (the papers give mm, mm²; converted here),
per sample at the predictor's own rate as in the papers.
"""

from __future__ import annotations

import math

import numpy as np

from rhmpc.predictors.fourier_init import (
    FitWindow,
    fit_covariance,
    fit_harmonics,
    initial_dual_state,
    initial_fourier_state,
    spd_inverse,
    wrap_phase,
)
from rhmpc.predictors.fourier_settings import EKF_PARAMETER_SETS as PARAMETER_SETS
from rhmpc.predictors.fourier_settings import Q_OMEGA_HRV, EKFSettings
from rhmpc.predictors.nonperiodic import (
    FourierPredictor,
    NonPeriodic,
    chi2_quantile,
    long_run_variance,
)

__all__ = ["PARAMETER_SETS", "Q_OMEGA_HRV", "EKFSettings", "FourierEKF"]

_TWO_PI = 2.0 * math.pi


class FourierEKF(FourierPredictor):
    """Time-varying Fourier-series EKF predictor, 1-D or 3-D with one shared ω."""

    Settings = EKFSettings
    PRESETS = PARAMETER_SETS

    def reset(self) -> None:
        super().reset()
        self.nis = math.nan  # normalised innovation squared of the last correction

    def _allocate(self, d: int) -> None:
        s = self.settings
        m = s.harmonics
        self.n_init = max(round(s.init_seconds / self.dt), 2 * (2 * m + 1))
        self._window, self._fit_count = FitWindow(self.n_init, d), 0
        hb = s.breathing_harmonics
        n0 = d * (2 * m + 1) + 1
        self.nx = n0 + (d * 2 * hb + 2 if hb else 0)
        self.iw = d * (m + 1)  # index of ω
        self.ib = n0 + np.arange(d * 2 * hb).reshape(d, 2 * hb)  # breathing a, b per axis
        self.iwb, self.itb = n0 + d * 2 * hb, n0 + d * 2 * hb + 1  # ω_b, θ_b
        cr = np.arange(d * (m + 1)).reshape(d, m + 1)
        self.ic, self.ir = cr[:, 0], cr[:, 1:]
        self.ith = self.iw + 1 + np.arange(d * m).reshape(d, m)
        harm = np.arange(1, m + 1, dtype=float)
        self._g = np.zeros(self.nx)
        self._g[self.ith] = harm * self.dt  # ∂θ/∂ω per step
        u2 = self.unit**2
        q = np.full(self.nx, s.q / u2)
        q[self.ith] = s.q_phase
        q[self.iw] = s.q_omega
        q = q if s.q_rate_hz is None else q * (self.dt * s.q_rate_hz)
        if s.q_omega_per_second is not None:
            q[self.iw] = s.q_omega_per_second * self.dt
        if hb:  # Richa's variances are per sample at 83.3 Hz
            q[self.ib] = s.q_breathing / u2 * (self.dt * 83.3)
            q[self.iwb] = s.q_omega_breathing * (self.dt * 83.3)
            q[self.itb] = 0.0
        self._q = q
        self._hb = np.arange(1.0, hb + 1.0)
        self._wb_lo, self._wb_hi = (_TWO_PI * f for f in s.breathing_band_hz)
        p_gate = s.gate_probability
        self._gate = math.inf if p_gate is None else chi2_quantile(p_gate, d)
        self._max_reject, self._rejected = max(1, round(s.gate_seconds / self.dt)), 0
        self._r = (s.sigma_r / self.unit) ** 2
        self._rest, self._hph = None, None
        if s.adaptive_r or s.residual_order:
            self._rest = NonPeriodic(d, self.dt, self._r, s.adaptive_r, s.residual_order,
                                     s.residual_forgetting, self.unit, s.omega_limits_hz[0],
                                     self.counts)
        self._harm = harm
        self._w_lo, self._w_hi = (_TWO_PI * f for f in s.omega_limits_hz)
        self._band_lo, self._band_hi = (_TWO_PI * f for f in s.band_hz)
        self.x = np.zeros(self.nx)
        self.P = np.eye(self.nx)
        self._Pdiag = np.einsum("ii->i", self.P)
        self._H = np.zeros((d, self.nx))
        self._H[np.arange(d), self.ic] = 1.0
        # views of the block-diagonal Jacobian: H_r[a] = sin θ_a, H_θ[a] = r_a cos θ_a
        self._H_r = np.einsum("aaj->aj", self._H[:, : self.iw].reshape(d, d, m + 1))[:, 1:]
        self._H_th = np.einsum("aaj->aj", self._H[:, self.iw + 1 : n0].reshape(d, d, m))
        self._H_b = np.einsum("aaj->aj", self._H[:, n0 : self.iwb].reshape(d, d, 2 * hb))
        self._bind_views()

    def _bind_views(self) -> None:
        """Reshaped views of ``self.x``: c (d,), r (d, m), θ (d, m)."""
        d, m = self.d, self.settings.harmonics
        cr = self.x[: self.iw].reshape(d, m + 1)
        n0 = self.iw + 1 + d * m
        self._c, self._rr, self._th = cr[:, 0], cr[:, 1:], self.x[self.iw + 1 : n0].reshape(d, m)
        self._ab = self.x[n0 : self.iwb].reshape(d, -1)  # [a_1..H_b, b_1..H_b] per axis

    # -- public state access ----------------------------------------------------
    @property
    def omega(self) -> float:
        """ω̂ [rad/s]."""
        return float(self.x[self.iw])

    @property
    def heart_rate_hz(self) -> float:
        """ω̂/2π [Hz]; NaN until initialised."""
        return float(self.x[self.iw]) / _TWO_PI if self.ready else math.nan

    @property
    def breathing_rate_hz(self) -> float:
        """ω̂_b/2π [Hz]; NaN without breathing model or until initialised."""
        if not (self.ready and self.settings.breathing_harmonics):
            return math.nan
        return float(self.x[self.iwb]) / _TWO_PI

    @property
    def offsets(self) -> np.ndarray:
        return self._c.copy()

    @property
    def amplitudes(self) -> np.ndarray:
        """``|r̂_{a,i}|`` as (d, m), in data units."""
        return np.abs(self._rr)

    @property
    def phases(self) -> np.ndarray:
        return self._th.copy()

    def set_state(self, x: np.ndarray, P: np.ndarray) -> None:
        """Start the filter at state ``x`` (n,) with covariance ``P`` (n, n), skipping the init."""
        if self.d is None:
            raise RuntimeError("set_state needs the dimension: give `dim` or one sample first")
        self.x[:] = np.asarray(x, dtype=float).reshape(self.nx)
        self.P[:] = np.asarray(P, dtype=float).reshape(self.nx, self.nx)
        self.ready = True

    def initial_covariance(self) -> np.ndarray:
        """P(T|T) of Yuen/Tuna: diag[σ_R²/N, σ₁²/i², σ_ω², σ_θ²] in data units."""
        s = self.settings
        p = np.empty(self.nx)
        p[self.ic] = self._r / self.n_init
        p[self.ir] = (s.sigma1_sq / self.unit**2) / self._harm**2
        p[self.iw] = s.sigma_omega_sq
        p[self.ith] = s.sigma_phase_sq
        if s.breathing_harmonics:
            p[self.ib] = s.sigma1_sq / self.unit**2
            p[self.iwb] = (_TWO_PI * 0.01) ** 2  # as the dual EKF's respiratory prior
            p[self.itb] = 0.0
        return np.diag(p)

    # -- the filter -------------------------------------------------------------
    def _initialise(self) -> None:
        """Fit the window (Yuen's start; also the re-fit after a lost lock)."""
        window, self._fit_count = self._window.oldest_first(), self._window.count
        s = self.settings
        x = np.zeros(self.nx)
        if s.breathing_harmonics:
            omega, c, r, th, wb, a, b = initial_dual_state(
                window,
                self.dt,
                s.harmonics,
                s.band_hz,
                s.breathing_harmonics,
                s.breathing_band_hz,
            )
            x[self.ib], x[self.iwb], x[self.itb] = np.hstack([a, b]), wb, 0.0
        else:
            omega, c, r, th = initial_fourier_state(window, self.dt, s.harmonics, s.band_hz)
        x[self.ic], x[self.ir], x[self.iw], x[self.ith] = c, r, omega, th
        self.set_state(x, self.initial_covariance())
        self._fit_omega = omega
        if s.fit_beats:
            self._refit_recent(window, omega)
        if s.p0_from_fit:
            self._covariance_from_fit(window, omega)
        if self._rest is not None:
            self._rest.restart()

    def _heart_samples(self, window: np.ndarray, omega: float) -> int:
        """Samples the heart series is fitted on: the last ``fit_beats`` beats, or all."""
        beats = self.settings.fit_beats
        n = len(window) if not beats else round(beats * _TWO_PI / (omega * self.dt))
        return max(2 * (2 * self.settings.harmonics + 1), min(len(window), n))

    def _refit_recent(self, window: np.ndarray, omega: float) -> None:
        """c, r, θ again from the last beats of the window, its breathing fit removed."""
        n = self._heart_samples(window, omega)
        heart = self._c.copy(), self._rr.copy()
        self._c[:], self._rr[:] = 0.0, 0.0
        rest = window[-n:] - self._model(np.arange(1.0 - n, 1.0))  # the window less breathing
        self._c[:], self._rr[:] = heart
        c, a, b = fit_harmonics(rest, self.dt, omega, self.settings.harmonics)
        self._c[:], self._rr[:], self._th[:] = c, np.hypot(a, b), np.arctan2(b, a)

    def _covariance_from_fit(self, window: np.ndarray, omega: float) -> None:
        """P(T|T) of c, r, θ and of the breathing a, b from the least-squares covariance
        s²_lr·(AᵀA)⁻¹ of the window fit, s²_lr the long-run variance of its residual per axis."""
        m, hb, P = self.settings.harmonics, self.settings.breathing_harmonics, self._Pdiag
        res = window - self._model(np.arange(1.0 - len(window), 1.0))
        s2 = np.maximum(long_run_variance(res), self._r)
        series = [(omega, m)] + ([(self.x[self.iwb], hb)] if hb else [])
        C = fit_covariance(len(window), self.dt, series)
        va, vb = np.diag(C)[1 : m + 1], np.diag(C)[m + 1 : 2 * m + 1]
        cab = np.diag(C, m)[1 : m + 1]
        a, b = self._rr * np.cos(self._th), self._rr * np.sin(self._th)  # (d, m)
        r2 = np.maximum(self._rr**2, 1e-150)  # r2² stays a normal float
        P[self.ic] = s2 * C[0, 0]  # r = |(a, b)|, θ = atan2(b, a): first-order propagation
        P[self.ir] = s2[:, None] * (a * a * va + 2 * a * b * cab + b * b * vb) / r2
        P[self.ith] = np.minimum(
            s2[:, None] * (a * a * vb - 2 * a * b * cab + b * b * va) / r2**2, math.pi**2)
        if hb:
            P[self.ib] = s2[:, None] * np.diag(C)[2 * m + 1 :]

    def _time_update(self) -> None:
        x, P, g, iw = self.x, self.P, self._g, self.iw
        w = x[iw]
        x[iw + 1 :] += g[iw + 1 :] * w
        wrap_phase(x[iw + 1 :])  # (g is zero on the breathing block: θ_b is advanced below)
        # F P Fᵀ with F = I + g e_ωᵀ:  P + g vᵀ + v gᵀ,  v = P e_ω + ½ P_ωω g
        v = P[:, iw] + (0.5 * P[iw, iw]) * g
        gv = np.multiply.outer(g, v)
        P += gv
        P += gv.T
        if self._hb.size:  # θ_b += ω_b Δt:  F = I + Δt e_θb e_ωbᵀ
            it, ib, dt = self.itb, self.iwb, self.dt
            x[it] = math.remainder(x[it] + dt * x[ib], _TWO_PI)
            P[it, :] += dt * P[ib, :]
            P[:, it] += dt * P[:, ib]
        self._Pdiag += self._q

    def _update(self, z: np.ndarray) -> None:
        rest = self._rest
        if rest is not None:
            rest.push(z)
        if not self.ready:
            self._collect(z)
            self._follow(learn=False)
            return
        self._window.push(z)
        self._time_update()
        accepted = self._correct(z)
        if accepted:
            self._keep_lock()
        elif rest is not None:
            rest.reject()
        self._follow(learn=accepted)

    def _rate(self) -> float:
        return float(self.x[self.iw])

    def _correct(self, z: np.ndarray) -> bool:
        """The EKF correction with sample z; False if the gate rejected it or S is not SPD."""
        x, P, H = self.x, self.P, self._H
        sin = np.sin(self._th)
        self._H_r[:] = sin
        np.multiply(self._rr, np.cos(self._th), out=self._H_th)
        nu = z - self._c - (self._rr * sin).sum(axis=1)  # innovation z − h(x⁻)
        hb = self._hb
        if hb.size:
            ph = hb * x[self.itb]
            sb, cb = np.sin(ph), np.cos(ph)
            a, b = self._ab[:, : hb.size], self._ab[:, hb.size :]
            self._H_b[:, : hb.size] = sb
            self._H_b[:, hb.size :] = cb
            H[:, self.itb] = (a * cb - b * sb) @ hb
            nu -= a @ sb + b @ cb
        PHt = P @ H.T
        S = H @ PHt
        self._hph = S.diagonal().copy()
        S.flat[:: self.d + 1] += self._r if self._rest is None else self._rest.r
        Sinv = spd_inverse(S)
        if Sinv is None:
            self._restart()
            return False
        Sinv_nu = Sinv @ nu
        self.nis = float(nu @ Sinv_nu)
        if self.nis > self._gate and self._rejected < self._max_reject:
            self.counts["innovation_rejected"] += 1
            self._rejected += 1
            return False
        self._rejected = 0
        K = PHt @ Sinv
        x += PHt @ Sinv_nu
        P -= K @ PHt.T
        P += P.T
        P *= 0.5
        wrap_phase(x[self.iw + 1 :])
        return True

    def _keep_lock(self) -> None:
        """Clamp ω̂_b and ω̂; re-fit when ω̂ left its band or locked on ω/2 (module docstring)."""
        x = self.x
        if self._hb.size and not self._wb_lo <= x[self.iwb] <= self._wb_hi:
            self.counts["breathing_clamped"] += 1
            x[self.iwb] = min(max(x[self.iwb], self._wb_lo), self._wb_hi)
        w = x[self.iw]
        if not math.isfinite(w):
            self._restart()
            return
        if not self._w_lo <= w <= self._w_hi:
            self.counts["omega_clamped"] += 1
            x[self.iw] = min(max(w, self._w_lo), self._w_hi)
        elif self._band_lo <= w <= self._band_hi and not self._subharmonic() and self._near_fit(w):
            return
        if self._window.usable():  # lost lock: ω̂ clamped, outside the FFT's band, or on ω/2
            self.counts["lock_refit"] += 1
            self._rejected = 0
            self._initialise()

    def _near_fit(self, w: float) -> bool:
        """ω̂ within [ω_fit/b, ω_fit·b] of the rate of the last fit (``rate_band`` b)."""
        b = self.settings.rate_band
        return b is None or self._fit_omega / b <= w <= self._fit_omega * b

    def _subharmonic(self) -> bool:
        """P₂ > P₁ (module docstring), once the window is all new since the last fit."""
        r = self._rr
        return (r.shape[1] > 1 and self._window.count - self._fit_count >= self.n_init
                and float(np.dot(r[:, 1], r[:, 1])) > float(np.dot(r[:, 0], r[:, 0])))

    def _restart(self) -> None:
        self.counts["ekf_reinit"] += 1
        self.ready = False
        self._window.clear()

    def _collect(self, z: np.ndarray | float) -> None:
        """Add a sample (or NaN) to the initialisation window; start once ≥ 80 % are valid."""
        self._window.push(z)
        if self._window.usable():
            self._initialise()

    def _missing(self) -> None:
        if self.ready:
            self._window.push(np.nan)
            self._time_update()
        else:
            self._collect(np.nan)
        self._rest_missing()

    def _model(self, k: np.ndarray) -> np.ndarray:
        """The Fourier model (eq. 2 with breathing) k samples ahead of the state, (len(k), d)."""
        k = np.asarray(k, dtype=float)[:, None, None]
        th = self._th[None] + (self._harm * (self.x[self.iw] * self.dt)) * k
        out = self._c[None, :] + (self._rr[None] * np.sin(th)).sum(axis=2)
        hb = self._hb
        if hb.size:
            ph = np.multiply.outer(self.x[self.itb] + self.x[self.iwb] * self.dt * k[:, 0, 0], hb)
            out += np.sin(ph) @ self._ab[:, : hb.size].T + np.cos(ph) @ self._ab[:, hb.size :].T
        return out

