"""Joint state estimation from encoders: a steady-state Kalman filter on the linear arm.

The encoders deliver quantised joint angles ``q̃ = Δ·round(q/Δ)``; differentiating them at
2 kHz would give velocity noise of Δ/Ts (0.27 rad/s for the PHANToM's elbow). Instead the
controller estimates ``x = [q − q0; q̇]`` with the model it already has (the MPC's
:class:`~rhmpc.robots.LinearArm`, valid because the nonlinearities are cancelled)::

    predict:  x̂⁻_{k+1} = A x̂_k + B u_k                     (u_k = applied τ_mpc)
    correct:  x̂_k     = x̂⁻_k + L (q̃_k − q0 − H x̂⁻_k),     H = [I 0]

``L`` is the steady-state Kalman gain for an acceleration disturbance of standard deviation
``acceleration_noise`` (the unmodelled part: model mismatch, friction residue) entering as
``[Ts²/2 I; Ts I] w`` and the quantisation noise variance Δ²/12.

Innovation gate (encoders that stick, a reading that is not finite)
    The innovation ν_j = q̃_j − q0_j − x̂⁻_j of a healthy encoder has the steady-state variance
    S_jj, S = H P⁻ Hᵀ + R (P⁻ the filter's a-priori covariance, R = diag(Δ²/12)). A reading
    with some abs(ν_j) > γ √S_jj, or not finite, is held out whole (the joints' encoders share
    one interface): the prediction stands in for it, x̂ = x̂⁻ (the innovation test of fault
    detection: Mehra & Peschon, *Automatica* 7(5), 1971; Willsky, *Automatica* 12(6), 1976).
    A stuck encoder shows as a reading that stays while the model, driven by the torque that
    acts, moves on: the filter absorbs a steady acceleration a as the innovation bias
    a Ts / L_v, so the gate sees an acceleration past γ √S L_v / Ts, which a loop fighting a
    stuck joint reaches as its torque grows. A reading held for ``reacquire_ticks`` whose joints
    that were past the gate when the hold began have all changed since is alive (a disturbance
    the model did not know, or a quantised reading flipping back a step, not a fault); a joint
    that the open-loop prediction carries past its gate during the hold is no suspect (an arm
    at rest reads the same). The estimate's angles then move to the reading, its velocity to
    the reading's mean over the hold, and the next ``reacquire_ticks`` readings are fused
    whatever their innovation while the filter settles. A reading held for ``fault_timeout``
    is an encoder fault: :attr:`JointObserver.faulted` tells the controller to brake (on the
    predicted velocity, the best it has).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from rhmpc.robots import LinearArm


@dataclass(frozen=True)
class ObserverSettings:
    """Velocity observer.

    Attributes
    ----------
    acceleration_noise : float
        Standard deviation of the unmodelled joint acceleration per tick [rad/s²].
    angle_noise : float
        Measurement noise used when the robot has no encoder model [rad].
    innovation_gate : float
        γ: a reading whose innovation exceeds γ √S_jj is held out [standard deviations of the
        innovation]; 0 fuses every finite reading.
    reacquire_ticks : int
        Ticks a reading is held before one that has changed is taken again [ticks].
    fault_timeout : float
        A reading held this long is an encoder fault: the controller brakes [s].
    """

    acceleration_noise: float = 20.0
    angle_noise: float = 1e-6
    innovation_gate: float = 5.0
    reacquire_ticks: int = 20
    fault_timeout: float = 0.05

    def __post_init__(self) -> None:
        for name in ("acceleration_noise", "angle_noise", "fault_timeout"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        gate = self.innovation_gate
        if not (isinstance(gate, int | float) and np.isfinite(gate) and gate >= 0):
            raise ValueError(f"innovation_gate must be a finite number >= 0, got {gate!r}")
        ticks = self.reacquire_ticks
        if isinstance(ticks, bool) or not isinstance(ticks, int) or ticks < 1:
            raise ValueError(f"reacquire_ticks must be an integer >= 1, got {ticks!r}")


class JointObserver:
    """Steady-state Kalman filter for ``x = [q − q0; q̇]`` from (quantised) joint angles, with
    an innovation gate (module docstring).

    Attributes
    ----------
    L : (2n, n) the steady-state Kalman gain
    gate : (n,) γ √S_jj, the largest innovation fused per joint [rad]
    held : int, ticks the reading has been held out in a row
    counts : dict
        ``held`` (readings held out), ``reacquired`` (readings taken again after a hold).
    reading : (n,) the angles the last correction fused: the encoders', or the prediction
        while the reading is held out [rad]
    """

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
        S = H @ P @ H.T + np.diag(meas_var)
        self.L = P @ H.T @ np.linalg.inv(S)
        gamma = self.settings.innovation_gate
        # off (γ = 0): every finite reading (the largest float, so that ±inf is held out)
        self.gate = (gamma * np.sqrt(np.diag(S)) if gamma > 0
                     else np.full(n, np.finfo(float).max))
        self.timeout_ticks = max(1, round(self.settings.fault_timeout / arm.Ts))
        self.Ts = arm.Ts
        self.n = n
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
        self.reading = self._q_in
        self._u_in = self._post_and_u[2 * n :]
        self._nu, self._abs_nu = np.zeros(n), np.zeros(n)
        self._gate_min = float(self.gate.min())
        self._first = np.zeros(n)  # the reading when it was first held
        self._suspect = np.zeros(n, dtype=bool)  # its joints past the gate then
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
        """Start from ``x`` (default: at rest at q0); no reading held, counts zero."""
        self.x_prior[:] = 0.0 if x is None else np.asarray(x, dtype=float)
        self.x[:] = self.x_prior
        self.held = 0
        self._grace = 0
        self.counts = {"held": 0, "reacquired": 0}

    @property
    def faulted(self) -> bool:
        """Whether the reading has been held for ``fault_timeout``: an encoder fault."""
        return self.held >= self.timeout_ticks

    def correct(self, q_measured: np.ndarray) -> np.ndarray:
        """Fuse the measured joint angles [rad]; returns the estimate x̂ = [q − q0; q̇].

        A reading past the innovation gate, or not finite, is held out: x̂ = x̂⁻ (module
        docstring). The returned array is the filter's own storage: it is overwritten by the
        next ``correct`` (copy it to keep it).
        """
        self._q_in[:] = q_measured
        nu = np.subtract(self._q_in, self.q0, out=self._nu)
        nu -= self.x_prior[: self.n]
        if self._grace and np.isfinite(nu).all():  # after a hold: fused whatever it says (if
            self._grace -= 1                           # it is a number), while it settles
        # every |ν_j| within the smallest gate is within its own (NaN is not): the exact test
        # of _hold only when that fails
        elif (self.held or not np.abs(nu, out=self._abs_nu).max() <= self._gate_min) \
                and self._hold(nu):
            return self.x
        return np.dot(self._correct_matrix, self._prior_q_one, out=self.x)

    def _hold(self, nu: np.ndarray) -> bool:
        """Whether the reading is held out (then x̂ = x̂⁻ and the prediction stands in for it);
        a reading held ``reacquire_ticks`` whose joints that were past the gate when the hold
        began have all changed since is taken again (a joint the open-loop prediction drifts
        away from during the hold is not a suspect: an arm at rest reads the same)."""
        q = self._q_in
        past = ~(np.abs(nu) <= self.gate)  # NaN is past
        if not past.any():
            self.held = 0
            return False
        suspect = self._suspect
        if self.held >= self.settings.reacquire_ticks and np.all(np.isfinite(q)) \
                and np.all(q[suspect] != self._first[suspect]):
            self._reacquire(q)
            return False
        if self.held == 0:
            self._first[:] = q
            suspect[:] = past
        self.held += 1
        self.counts["held"] += 1
        np.add(self.q0, self.x_prior[: self.n], out=q)
        self.x[:] = self.x_prior
        return True

    def _reacquire(self, q: np.ndarray) -> None:
        """Take a reading that moved again: the angles become the estimate's, the velocity the
        reading's mean over the hold (when its first reading was finite), and the next
        ``reacquire_ticks`` readings are fused ungated while the filter settles."""
        n = self.n
        if np.all(np.isfinite(self._first)):
            np.subtract(q, self._first, out=self.x_prior[n:])
            self.x_prior[n:] /= self.held * self.Ts
        np.subtract(q, self.q0, out=self.x_prior[:n])
        self.held = 0
        self._grace = self.settings.reacquire_ticks
        self.counts["reacquired"] += 1

    def predict(self, u: np.ndarray) -> None:
        """Propagate with the applied MPC torque u [N·m] to the next tick."""
        self._u_in[:] = u
        np.dot(self._predict_matrix, self._post_and_u, out=self.x_prior)
