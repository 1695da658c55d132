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
    is an encoder fault: the controller brakes (on the predicted velocity, the best it has).

Delayed readings (a robot behind a middleware)
    A reading of tick m that comes at tick k > m is fused into the prior of its own tick and
    carried forward through the torques that acted since, x̂⁻_{t+1} = A x̂_t + B u_t for
    t = m … k − 1, with no reading at the ticks after m (the recalculation of Larsen, Andersen,
    Ravn & Poulsen, "Incorporation of time delayed measurements in a discrete-time Kalman
    filter", *Proc. 37th IEEE CDC*, 1998): the estimate the filter would have made with that
    reading on time and none since. Readings up to ``max_delay`` late are fused; an older
    one, or one not newer than the last taken, is none.
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
    max_delay : float
        The latest a reading may come after its instant and still be fused [s]. The default,
        20 ms, holds the round trips of a middleware such as ROS 2 (a DDS round trip between
        two processes of one host takes about 0.3 ms, its tail a few ms) with a margin, and
        stays below ``fault_timeout``.
    """

    acceleration_noise: float = 20.0
    angle_noise: float = 1e-6
    innovation_gate: float = 5.0
    reacquire_ticks: int = 20
    fault_timeout: float = 0.05
    max_delay: float = 0.02

    def __post_init__(self) -> None:
        for name in ("acceleration_noise", "angle_noise", "fault_timeout"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        gate = self.innovation_gate
        if not (isinstance(gate, int | float) and np.isfinite(gate) and gate >= 0):
            raise ValueError(f"innovation_gate must be a finite number >= 0, got {gate!r}")
        delay = self.max_delay
        if not (isinstance(delay, int | float) and np.isfinite(delay) and delay >= 0):
            raise ValueError(f"max_delay must be a finite number >= 0, got {delay!r}")
        ticks = self.reacquire_ticks
        if isinstance(ticks, bool) or not isinstance(ticks, int) or ticks < 1:
            raise ValueError(f"reacquire_ticks must be an integer >= 1, got {ticks!r}")


class JointObserver:
    """Steady-state Kalman filter for ``x = [q − q0; q̇]`` from (quantised) joint angles, with
    an innovation gate (module docstring): its gains, which the controller's library runs
    (``rhmpc.c``).

    Attributes
    ----------
    L : (2n, n) the steady-state Kalman gain
    S : (n, n) the innovation's steady-state covariance H P⁻ Hᵀ + R [rad²]
    gate : (n,) γ √S_jj, the largest innovation fused per joint [rad]
    timeout_ticks : int, ticks a reading is held before it is an encoder fault
    delay_ticks : int, the most ticks a reading may come late and be fused
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
        self.S = H @ P @ H.T + np.diag(meas_var)
        self.L = P @ H.T @ np.linalg.inv(self.S)
        gamma = self.settings.innovation_gate
        # off (γ = 0): every finite reading (the largest float, so that ±inf is held out)
        self.gate = (gamma * np.sqrt(np.diag(self.S)) if gamma > 0
                     else np.full(n, np.finfo(float).max))
        self.timeout_ticks = max(1, round(self.settings.fault_timeout / arm.Ts))
        self.delay_ticks = round(self.settings.max_delay / arm.Ts)
        self.Ts, self.n = arm.Ts, n
