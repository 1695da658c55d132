"""Joint state estimation from encoders: a steady-state Kalman filter on the linear arm.

The encoders deliver quantised joint angles ``q̃ = Δ·round(q/Δ)``; differentiating them at
2 kHz would give velocity noise of Δ/Ts (0.27 rad/s for the PHANToM's elbow). Instead the
controller estimates ``x = [q − q0; q̇]`` with the model it already has (the MPC's
:class:`~robots.LinearArm`, valid because the nonlinearities are cancelled)::

    predict:  x̂⁻_{k+1} = A x̂_k + B u_k                     (u_k = applied τ_mpc)
    correct:  x̂_k     = x̂⁻_k + L (q̃_k − q0 − H x̂⁻_k),     H = [I 0]

``L`` is the steady-state Kalman gain for an acceleration disturbance of standard deviation
``acceleration_noise`` (the unmodelled part: model mismatch, friction residue) entering as
``[Ts²/2 I; Ts I] w`` and the quantisation noise variance Δ²/12.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from robots import LinearArm


@dataclass(frozen=True)
class ObserverSettings:
    """Velocity observer.

    Attributes
    ----------
    acceleration_noise : float
        Standard deviation of the unmodelled joint acceleration per tick [rad/s²].
    angle_noise : float
        Measurement noise used when the robot has no encoder model [rad].
    """

    acceleration_noise: float = 20.0
    angle_noise: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("acceleration_noise", "angle_noise"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")


class JointObserver:
    """Steady-state Kalman filter for ``x = [q − q0; q̇]`` from (quantised) joint angles."""

    def __init__(
        self,
        arm: LinearArm,
        encoder_resolution: np.ndarray | None,
        settings: ObserverSettings | None = None,
    ) -> None:
        self.settings = settings or ObserverSettings()
        n = arm.nu
        self.A, self.B, self.q0 = arm.A, arm.B, arm.q0
        if encoder_resolution is None:
            meas_var = np.full(n, self.settings.angle_noise**2)
        else:
            meas_var = np.asarray(encoder_resolution, dtype=float) ** 2 / 12.0
        G = np.vstack([0.5 * arm.Ts**2 * np.eye(n), arm.Ts * np.eye(n)])
        Qw = self.settings.acceleration_noise**2 * G @ G.T
        H = np.hstack([np.eye(n), np.zeros((n, n))])
        P = scipy.linalg.solve_discrete_are(self.A.T, H.T, Qw, np.diag(meas_var))
        self.L = P @ H.T @ np.linalg.inv(H @ P @ H.T + np.diag(meas_var))
        # Both steps as one mat-vec on preallocated storage (allocation-free at 2 kHz):
        #   correct: x̂ = [I − L H, L, −L q0] [x̂⁻; q̃; 1]      predict: x̂⁻ = [A, B] [x̂; u]
        self._correct_matrix = np.hstack([np.eye(2 * n) - self.L @ H, self.L,
                                          -(self.L @ self.q0)[:, None]])
        self._predict_matrix = np.hstack([self.A, self.B])
        self._prior_q_one = np.zeros(3 * n + 1)  # [x̂⁻; q̃; 1]
        self._prior_q_one[-1] = 1.0
        self._post_and_u = np.zeros(3 * n)  # [x̂; u]
        self.x_prior = self._prior_q_one[: 2 * n]
        self.x = self._post_and_u[: 2 * n]
        self._q_in = self._prior_q_one[2 * n : 3 * n]
        self._u_in = self._post_and_u[2 * n :]
        self.reset()

    @property
    def correct_matrix(self) -> np.ndarray:
        """[I − L H, L, −L q0]: the correction as one mat-vec on [x̂⁻; q̃; 1] (read-only view)."""
        view = self._correct_matrix.view()
        view.flags.writeable = False
        return view

    @property
    def predict_matrix(self) -> np.ndarray:
        """[A, B]: the prediction as one mat-vec on [x̂; u] (read-only view)."""
        view = self._predict_matrix.view()
        view.flags.writeable = False
        return view

    def reset(self, x: np.ndarray | None = None) -> None:
        """Start from ``x`` (default: at rest at q0)."""
        self.x_prior[:] = 0.0 if x is None else np.asarray(x, dtype=float)
        self.x[:] = self.x_prior

    def correct(self, q_measured: np.ndarray) -> np.ndarray:
        """Fuse the measured joint angles [rad]; returns the estimate x̂ = [q − q0; q̇].

        A reading that is not finite (an encoder fault) is not fused: the estimate is the
        prediction x̂⁻, so that the state stays finite. The returned array is the filter's own
        storage: it is overwritten by the next ``correct`` (copy it to keep it).
        """
        self._q_in[:] = q_measured
        if not np.isfinite(np.vdot(self._q_in, self._q_in)):
            self.x[:] = self.x_prior
            return self.x
        return np.dot(self._correct_matrix, self._prior_q_one, out=self.x)

    def predict(self, u: np.ndarray) -> None:
        """Propagate with the applied MPC torque u [N·m] to the next tick."""
        self._u_in[:] = u
        np.dot(self._predict_matrix, self._post_and_u, out=self.x_prior)
