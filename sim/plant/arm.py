"""The ideal plant: the full nonlinear arm, the torque applied as commanded.

With the joint torque ``τ`` (clipped to the actuator limits) held over a control tick::

    M(q) q̈ + C(q, q̇) q̇ + g(q) = τ − Sᵀ (D ω + F_c tanh(ω / v_s)),   ω = S q̇

``M`` includes the reflected rotor inertia (armature); ``D`` is viscous damping and ``F_c``
Coulomb friction of each motor, acting on its output rate ω (``S`` the robot's motor map, the
identity where each joint has its own motor), smoothed by ``tanh`` over the velocity ``v_s``
(``PlantSettings.friction_smoothing``) so that the ODE stays integrable. It is the hardware-like
plant's equation (:mod:`rhmpc.sim.plant.hardware`) with every effect at its neutral value: the
command the torque (gain 1, the motor torques S⁻ᵀτ), no delay, no stiction peak, rigid cables;
integrated by the same kernel (:mod:`rhmpc.sim.plant.kernel`): explicit midpoint steps of
``Ts / substeps`` (:func:`rhmpc.sim.plant.settings.integration_steps`). The controller's
cancellation of these terms, with its own model, is :mod:`rhmpc.control.cancellation`.
"""
from __future__ import annotations

import numpy as np

from rhmpc.robots import Robot
from rhmpc.sim.plant.kernel import Chain, Drive, state
from rhmpc.sim.plant.settings import PlantSettings, integration_steps


class ArmPlant:
    """The ideal plant (module equation) of ``robot`` over control ticks of ``Ts`` seconds.

    ``q`` and ``v`` [rad, rad/s] read the state (copies) and can be assigned; ``saturated``
    tells whether the last step clipped the torque.
    """

    def __init__(self, robot: Robot, Ts: float, settings: PlantSettings | None = None) -> None:
        self.robot, self.Ts = robot, float(Ts)
        self.settings = settings or PlantSettings()
        S, chain = robot.motor_map, Chain(robot.model)
        S_inv = np.linalg.inv(S)
        inertia = np.diag(S_inv.T @ chain.mass(robot.q0) @ S_inv)  # J on each motor [kg·m²]
        steps = integration_steps(self.settings, self.Ts, inertia, robot.coulomb_friction)
        self._drive = Drive(chain, self.Ts, steps, motor_map=S,
                            gain=1.0, coulomb=robot.coulomb_friction, damping=robot.damping,
                            stiction_ratio=1.0, stribeck_velocity=1.0,
                            smoothing_velocity=self.settings.friction_smoothing, q0=robot.q0,
                            torque_limit=robot.torque_limit, command_map=S_inv.T)
        self._shape = (robot.nv,)
        self._counts = np.empty(robot.nv)  # the encoders' counts, q / Δ rounded
        self.saturated = False

    q = state(0, "Joint angles [rad].")
    v = state(1, "Joint rates [rad/s].")

    def reset(self, q: np.ndarray | None = None, v: np.ndarray | None = None) -> None:
        """Place the arm at ``q`` (default home) with velocity ``v`` (default rest)."""
        self.q = self.robot.check_posture(self.robot.q0 if q is None else q)
        self.v = 0.0 if v is None else v

    def encoders(self) -> np.ndarray:
        """The encoders' joint angles q̃ = Δ·round(q/Δ) [rad] (q without an encoder model)."""
        q, res = self._drive.x[:self._shape[0]], self.robot.encoder_resolution
        if res is None:
            return q.copy()
        counts = np.rint(np.divide(q, res, out=self._counts), out=self._counts)
        return res * counts

    def run_ticks(self, controller, tick: int, rows: dict) -> None:
        """The closed loop's ticks from ``tick`` on, one per row of ``rows``, in C: the encoders,
        ``controller``'s step and this plant's tick (:meth:`~rhmpc.sim.plant.kernel.Drive.run`),
        the same numbers as :meth:`encoders`, the controller's ``step`` and :meth:`step`."""
        self.saturated = self._drive.run(controller, self.robot.encoder_resolution, tick, rows)

    def step(self, tau: np.ndarray) -> None:
        """Advance one control tick with ``tau`` [N·m] clipped to ±``torque_limit`` and held."""
        if np.shape(tau) != self._shape:
            raise ValueError(f"tau must have shape {self._shape}, got {np.shape(tau)}")
        self.saturated = self._drive.tick(tau)
