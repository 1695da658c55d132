"""Dual (respiratory + cardiac) time-varying Fourier-series EKF (Richa, Bó & Poignet 2010, §I-C/D).

Model, per axis (eq. 1), two frequencies shared by all axes:

    y(t) = c_r + Σ_{h=1}^{H_r} [a_h sin hθ_r + b_h cos hθ_r]
               + Σ_{h=1}^{H_c} [d_h sin hθ_c + e_h cos hθ_c],

θ_r, θ_c the accumulated phases (θ ← θ + ωΔt, Richa's Σ_k ω(k)).  All coefficients and both
frequencies are random walks (eq. 2, P⁻ = P + Q); the correction is eqs. (3)–(5) with
C = ∂y/∂x.  Deviation from the paper: the two phases are carried as (noise-free) states, so
that the frequency enters through the transition F (θ += ωΔt) and its Jacobian is exact; with
the phases held outside the state Richa's identity transition is recovered.

Parameters (Richa §I-D): H_r = 3, H_c = 5; process variances 1e-5 mm² (respiratory
coefficients), 1e-6 mm² (offset), 1e-5 mm² (cardiac coefficients), 1e-8 (rad/sample)²
(frequencies), R = 0.1 mm², all per sample at Richa's ``83.3`` Hz; stored in SI (m², (rad/s)²:
``1e-8·83.3² = 6.94e-5``) and rescaled to the predictor's rate by ``dt · q_rate_hz``.  The initial
covariance is not given by Richa: ``p0_coefficient``, ``p0_offset``, ``p0_omega_*``.  The
papers' setting is the parameter set ``richa2010`` (zero start, ``init_seconds=None``).

Initialisation (``init_seconds`` = 10 s, as Yuen's EKF,
:func:`rhmpc.predictors.fourier_init.initial_dual_state`): ω̂_r by FFT in ``respiratory_band_hz``,
then (the respiratory fit removed) ω̂_c in ``cardiac_band_hz``, and c_r, a, b, d, e by least
squares with θ_r = θ_c = 0 at the newest sample; the forecast holds the newest sample until
then (over the first breath of 3-D motion with breathing, the respiratory sin/cos are nearly
collinear with the offset, which a zero start cannot separate).  The respiratory coefficients
and the offset then start at the fit's least-squares covariance s_a²·(ΦᵀΦ)⁻¹, the cardiac ones
at ``p0_coefficient`` (flat priors would let the first innovations re-fit the breathing).

Outliers (as :mod:`rhmpc.predictors.ekf_fourier`): a sample whose normalised innovation squared
exceeds the χ²_d quantile ``gate_probability`` is not used (``innovation_rejected``); after
``gate_seconds`` of consecutive rejections samples are used again.

Re-fit on lost lock: the last ``init_seconds`` of samples are kept; when ω̂_c or ω̂_r leaves the
band the initialisation's FFT searches (36–180 beats/min, 6–30 breaths/min), the state and
covariance are fitted again from that window (``lock_refit``); Richa observe that an
arrhythmia "is interpreted as a drastic phase change" (§II-C). A locked filter is unchanged.
A re-fit costs a window's FFT searches and fits (a
few milliseconds), so a lock lost again soon after is not re-fitted at once: after k re-fits
in a row the next waits min(2^(k−1) beats, the window) of samples (binary exponential
back-off; the lost samples are counted ``refit_deferred``, the rates meanwhile clamped to the
bands the fit searches), and a lock held for a beat ends the run of re-fits. Motion the model
cannot lock to then costs a re-fit per window, not one per sample.

Motion that is not periodic (``adaptive``, the default parameter set), as the ``ekf``'s
(:mod:`rhmpc.predictors.ekf_fourier`): R follows the long-run variance of the current state's
residual over the last beat less H P⁻ Hᵀ (``adaptive_r``, :mod:`rhmpc.predictors.nonperiodic`); an
AR(16) model of that residual with the model's increments as input adds to the forecast
(``residual_order``); the offset and cardiac series are fitted on the window's last 3 beats
(``fit_beats``); ω̂_c leaving [ω₀/1.5, 1.5 ω₀] of the fitted ω₀ is a lost lock (``rate_band``).
``benchmarks/invivo_regime.py`` measures ``adaptive`` against ``fitted`` (without these parts).

Cost per update: O(n²·d) with n = d(2H_r + 2H_c + 1) + 4 (55 for d = 3).
"""

from __future__ import annotations

import math

import numpy as np

from rhmpc.predictors.fourier_init import (
    FitWindow,
    fit_harmonics,
    initial_dual_state,
    spd_inverse,
    wrap_phase,
)
from rhmpc.predictors.fourier_settings import DUAL_PARAMETER_SETS as PARAMETER_SETS
from rhmpc.predictors.fourier_settings import DualEKFSettings
from rhmpc.predictors.nonperiodic import (
    FourierPredictor,
    NonPeriodic,
    chi2_quantile,
    long_run_variance,
)

__all__ = ["PARAMETER_SETS", "DualEKFSettings", "DualFourierEKF"]

_TWO_PI = 2.0 * math.pi


class DualFourierEKF(FourierPredictor):
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
        p_gate = s.gate_probability
        self._gate = math.inf if p_gate is None else chi2_quantile(p_gate, d)
        self._max_reject, self._rejected = max(1, round(s.gate_seconds / self.dt)), 0
        self._c_lo, self._c_hi = (_TWO_PI * f for f in s.cardiac_band_hz)
        self._r_lo, self._r_hi = (_TWO_PI * f for f in s.respiratory_band_hz)
        if s.init_seconds is not None:
            n = max(round(s.init_seconds / self.dt), 2 * k)
            self._window = FitWindow(n, d)
        self._rest, self._hph, self._fit_omega = None, None, math.nan
        self._refits = self._refit_wait = self._locked = 0  # the re-fit's back-off
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
        if accepted and s.init_seconds is not None:
            self._relock()
        elif self._rest is not None:
            self._rest.reject()
        self._follow(learn=accepted)

    def _relock(self) -> None:
        """Re-fit on a lost lock, with the back-off of the module docstring."""
        beat = max(1, round(_TWO_PI / (max(self.x[self.iwc], self._c_lo) * self.dt)))
        if not self._lost():
            self._locked += 1
            if self._locked >= beat:
                self._refits = 0
            return
        self._locked = 0
        if self._refit_wait > 0:  # meanwhile the rates stay within the bands the fit searches
            self._refit_wait -= 1
            self.counts["refit_deferred"] += 1
            self.x[self.iwc] = min(max(self.x[self.iwc], self._c_lo), self._c_hi)
            self.x[self.iwr] = min(max(self.x[self.iwr], self._r_lo), self._r_hi)
        elif self._fit():
            self.counts["lock_refit"] += 1
            self._refits += 1
            self._refit_wait = min(2 ** (self._refits - 1) * beat, len(self._window.samples))

    def _rate(self) -> float:
        return float(self.x[self.iwc])

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
        self._rest_missing()

    def _model(self, k: np.ndarray) -> np.ndarray:
        """Eq. (1) k samples ahead of the state (any k, past ones negative), (len(k), d)."""
        k, x = np.asarray(k, dtype=float), self.x
        phi = self._basis(
            x[self.itr] + k * x[self.iwr] * self.dt, x[self.itc] + k * x[self.iwc] * self.dt
        )
        return phi @ self._coef.T

    @property
    def heart_rate_hz(self) -> float:
        """Cardiac frequency estimate ω̂_c/2π [Hz]; NaN before the first sample."""
        return float(self.x[self.iwc] / _TWO_PI) if self.ready else math.nan

    @property
    def frequencies_hz(self) -> tuple[float, float]:
        """(respiratory, cardiac) frequency estimates [Hz]."""
        return float(self.x[self.iwr] / _TWO_PI), float(self.x[self.iwc] / _TWO_PI)
