"""A hardware-like plant: I/O delay, DAC, current amplifier, friction with stiction, cables.

The plant as :class:`~rhmpc.sim.plant.arm.ArmPlant` (encoders, step), with what the ideal plant
leaves out between the controller's torque and the arm. Per motor k, with
the motors' output angles θ = S (q − q0) (S the robot's motor map), transmission ratio η_k and
torque constant K_t:

1. **I/O delay** of ``d`` ticks: the torque τ_i commanded at tick i reaches the DAC at tick
   i + d and acts over the tick after it (``d = 1``: computed at i, acting over i + 1).
2. **DAC**: the current command i*_k = (S⁻ᵀ τ)_k / (η_k K_t) is rounded to the DAC's step
   2 I_max / 2^b and clipped to ±I_max.
3. **Current-mode amplifier**: the winding current follows the command as a first-order lag,
   i̇ = (i* − i) / τ_e, τ_e = L/R (exact over the tick: i* is held), and the motor's torque on
   its output coordinate is τ_m = η K_t i.
4. **Friction** on each motor's output rate ω, Coulomb with stiction (a Stribeck peak)::

       f(ω) = D ω + [F_c + (F_s − F_c) exp(−(ω / v_S)²)] tanh(ω / v_s)

5. **Cables** (optional): each motor's rotor, reflected inertia J_r = η² J_m, drives its output
   coordinate through a spring k and damper c (a two-mass model). Rigid::

       M(q) q̈ + h(q, q̇) = Sᵀ (τ_m − f(S q̇))

   With cables, rotor angle θ_r and M_l = M − Sᵀ diag(J_r) S the links alone::

       τ_s = k (θ_r − S (q − q0)) + c (θ̇_r − S q̇)
       M_l(q) q̈ + h(q, q̇) = Sᵀ τ_s,      J_r θ̈_r = τ_m − τ_s − f(θ̇_r)

   k follows from the resonance f_r: k = (2π f_r)² J_r J_l / (J_r + J_l), J_l the links'
   inertia on that motor's coordinate at home (the other motors held); c = 2ζ √(k J_r J_l /
   (J_r + J_l)).
6. **Encoders** on the motor shafts count θ (rigid) or θ_r (cables): q̃ = q0 + S⁻¹ Δ round(θ/Δ).

The kernel (:mod:`rhmpc.sim.plant.kernel`) integrates these equations by explicit midpoint steps,
each with the current's exact mean over the step; this module holds the delay, the DAC and the
encoders. The controller is unchanged: it knows its own I/O delay (its observer predicts with the
torque that acts over each tick), not what the DAC, amplifier and cables make of it.
"""

from __future__ import annotations

import math

import numpy as np

from rhmpc.robots import LinearArm, Robot
from rhmpc.sim.plant.kernel import Chain, Drive, state
from rhmpc.sim.plant.settings import PlantSettings, integration_steps


def dac_step(settings: PlantSettings) -> float:
    """The DAC's step 2 I_max / 2^bits [A] (0: no quantisation)."""
    return 2.0 * settings.dac_range / 2**settings.dac_bits if settings.dac_bits else 0.0


def cable_stiffness(resonance: float, rotor: np.ndarray, link: np.ndarray,
                    damping_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """(k, c) of two-mass cables with resonance ``resonance`` [Hz] between rotor inertias
    ``rotor`` and link inertias ``link`` [kg·m²]: k = ω² J_r J_l/(J_r + J_l), c = 2ζ√(k J)."""
    reduced = rotor * link / (rotor + link)
    k = (2 * math.pi * resonance) ** 2 * reduced
    return k, 2 * damping_ratio * np.sqrt(k * reduced)


class HardwarePlant:
    """The hardware-like plant (module equations): torques in, encoder angles out.

    Parameters
    ----------
    robot : Robot
        The true arm; it must have gear ratios, a motor map and encoders.
    Ts : float
        Control period [s].
    settings : PlantSettings
        The plant's quantities and the effects that are on.

    Raises
    ------
    ValueError
        A robot without drives, or no dynamics kernel (:mod:`rhmpc.sim.plant.kernel`).
    """

    def __init__(self, robot: Robot, Ts: float, settings: PlantSettings) -> None:
        if robot.gear_ratio is None or robot.encoder_resolution is None:
            raise ValueError(f"the hardware plant needs the robot's drives (gear ratios, "
                             f"encoders); robot {robot.name!r} has none")
        self.robot, self.Ts, self.settings = robot, float(Ts), settings
        S, n = robot.motor_map, robot.nv
        self._S, self._S_inv = S, np.linalg.inv(S)
        chain = Chain(robot.model)
        gravity = chain.rnea(robot.q0, np.zeros(n), np.zeros(n))  # g(q0) [N·m]
        M = chain.mass(robot.q0)
        self._cables = cables = self._cable_model(M) if settings.cable_resonance > 0 else None
        inertia = (robot.rotor_inertia if cables is not None
                   else np.diag(self._S_inv.T @ M @ self._S_inv))
        steps = integration_steps(settings, self.Ts, inertia, robot.coulomb_friction)
        gain, drive = self._command()
        self._drive = Drive(chain, self.Ts, steps, motor_map=S, gain=gain,
                            coulomb=robot.coulomb_friction, damping=robot.damping,
                            stiction_ratio=settings.stiction_ratio,
                            stribeck_velocity=settings.stribeck_velocity,
                            smoothing_velocity=settings.friction_smoothing, q0=robot.q0,
                            current_lag=settings.current_time_constant, cables=cables, **drive)
        held = self._S_inv.T @ gravity  # the motors hold the arm against gravity at rest
        if cables is not None:
            self.theta_r = held / cables[1]  # the cables' twist that holds it
        self._drive.current[:] = held / gain
        self._pending = [gravity] * settings.delay_ticks
        self.saturated = False
        res = robot.encoder_resolution  # the encoders' counts: Δ⁻¹ S (q − q0), and back
        self._to_counts, self._from_counts = S / res[:, None], self._S_inv * res
        self._counts0, self._q0, self._res, self._n = self._to_counts @ robot.q0, robot.q0, res, n
        self._read: tuple[bytes, np.ndarray] = (b"", np.zeros(n))  # (state, its reading)

    def _cable_model(self, M: np.ndarray) -> tuple:
        """(J_r, k, c) of the cables on each motor (:func:`cable_stiffness`), from M(q0)."""
        robot, S_inv = self.robot, self._S_inv
        M_l = M - robot.motor_map.T @ np.diag(robot.rotor_inertia) @ robot.motor_map
        link = np.diag(S_inv.T @ M_l @ S_inv)
        return (robot.rotor_inertia, *cable_stiffness(
            self.settings.cable_resonance, robot.rotor_inertia, link,
            self.settings.cable_damping_ratio))

    def _command(self) -> tuple[np.ndarray, dict]:
        """The output torque per unit of command, and the command's map and limits: with a
        current drive i* = S⁻ᵀ τ / (η K_t) [A], within ±I_max and rounded to the DAC's step;
        without, the motor torques S⁻ᵀ τ [N·m] of τ within the robot's limits."""
        s, robot = self.settings, self.robot
        if not s.torque_constant:
            return np.ones(robot.nv), {"command_map": self._S_inv.T,
                                       "torque_limit": robot.torque_limit}
        gain = robot.gear_ratio * s.torque_constant  # output torque per ampere
        return gain, {"command_map": self._S_inv.T / gain[:, None],
                      "full_scale": s.dac_range, "dac_step": dac_step(s)}

    q_arm = state(0, "The arm's joint angles [rad].")
    v = state(1, "The arm's joint rates [rad/s].")
    theta_r = state(2, "The rotors' angles on the output coordinates, with cables [rad].")
    omega_r = state(3, "The rotors' rates on the output coordinates, with cables [rad/s].")

    @property
    def current(self) -> np.ndarray:
        """The winding currents [A]."""
        return self._drive.current.copy()

    @property
    def k(self) -> np.ndarray:
        """The cables' stiffness [N·m/rad] (zeros: rigid)."""
        return np.zeros(self.robot.nv) if self._cables is None else self._cables[1]

    def encoders(self) -> np.ndarray:
        """q̃ = q0 + S⁻¹ Δ round(θ/Δ): joint angles from the motor encoders [rad], θ = S (q −
        q0) rigid, θ_r with cables."""
        x, n = self._drive.x, self._n
        state = x.tobytes()
        if state != self._read[0]:  # read once per state: the controller's and the score's
            if self._cables is None:
                counts = np.rint(self._to_counts @ x[:n] - self._counts0)
            else:
                counts = np.rint(x[2 * n:3 * n] / self._res)
            self._read = (state, self._q0 + self._from_counts @ counts)
        return self._read[1].copy()

    @property
    def q(self) -> np.ndarray:
        """The joint angles the loop scores [rad]: the arm's (``q_arm``), or the encoders'
        (``PlantSettings.error_from``)."""
        return self.encoders() if self.settings.error_from == "encoders" else self.q_arm

    def step(self, tau: np.ndarray) -> None:
        """The I/O delay, the DAC, the amplifier and one tick of the arm with ``tau`` [N·m]."""
        self._pending.append(np.array(tau, dtype=float))
        self.saturated = self._drive.tick(self._pending.pop(0))


class LinearPlant:
    """The MPC's own linear model as the plant (Tuna et al.'s Table I plant, "a linearized,
    reduced order model of the actual hardware").

    The arm is x⁺ = A x + B τ (the :class:`~rhmpc.robots.LinearArm`, gravity, Coriolis and friction
    absent, so nothing is cancelled), τ clipped to the torque limits; the encoders quantise
    q = q0 + x_q per joint. The loop scores the forward kinematics of q.
    """

    def __init__(self, robot: Robot, arm: LinearArm) -> None:
        self.robot, self.arm = robot, arm
        self._x = np.zeros(arm.nx)
        self._limit = robot.torque_limit
        self.saturated = False

    @property
    def q(self) -> np.ndarray:
        """The plant's joint angles q0 + x_q [rad]."""
        return self.arm.q0 + self._x[: self.arm.nu]

    def encoders(self) -> np.ndarray:
        """The quantised joint angles Δ·round(q/Δ) [rad]."""
        q, res = self.q, self.robot.encoder_resolution
        return q if res is None else res * np.round(q / res)

    def step(self, tau: np.ndarray) -> None:
        """x⁺ = A x + B clip(τ)."""
        applied = np.clip(tau, -self._limit, self._limit)
        self.saturated = bool(np.any(applied != tau))
        self._x = self.arm.A @ self._x + self.arm.B @ applied
