"""The ideal plant: the full nonlinear arm, the torque applied as commanded.

With the joint torque ``τ`` (clipped to the actuator limits) held over a control tick::

    M(q) q̈ + C(q, q̇) q̇ + g(q) = τ − Sᵀ (D ω + F_c tanh(ω / v_s)),   ω = S q̇

``M`` includes the reflected rotor inertia (armature); ``D`` is viscous damping and ``F_c``
Coulomb friction of each motor, acting on its output rate ω (``S`` the robot's motor map, the
identity where each joint has its own motor), smoothed by ``tanh`` over the stiction velocity
``v_s`` so that the ODE stays integrable. It is the hardware-like plant's equation
(:mod:`rhmpc.sim.plant.hardware`) with the current equal to the command (gain 1, the motor torques
S⁻ᵀτ), no stiction peak and rigid cables, integrated by the same kernel
(:mod:`rhmpc.sim.plant.kernel`): explicit midpoint steps of ``Ts / substeps``. The controller's
cancellation of these terms, with its own model, is :mod:`rhmpc.control.cancellation`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.robots import Robot
from rhmpc.sim.plant.kernel import Chain, Drive, state

MODELS = ("ideal", "linear", "hardware")


@dataclass(frozen=True)
class PlantSettings:
    """Which plant, and the ideal plant's integration and friction.

    Attributes
    ----------
    model : str
        ``"ideal"``: the nonlinear arm, the torque applied as commanded (this module);
        ``"linear"``: the MPC's own linear model as the plant (Tuna et al.'s Table I
        simulation); ``"hardware"``: the arm behind an I/O delay, a DAC, a current amplifier,
        friction with stiction and optionally compliant cables (:mod:`rhmpc.sim.plant.hardware`,
        its settings in ``HardwareSettings``).
    substeps : int
        Explicit-midpoint steps per control tick; the step is ``Ts / substeps`` [s]. Two steps
        keep the local error per tick below 0.5 µm at the end-effector against a fine RK4
        (``tests/sim/plant/test_plant.py``).
    stiction_velocity : float
        Velocity scale ``v_s`` of the smoothed Coulomb friction [rad/s].
    """

    substeps: int = 2
    stiction_velocity: float = 5e-3
    model: str = "ideal"

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"unknown plant model {self.model!r}; valid: {', '.join(MODELS)}")
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, int) \
                or self.substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1, got {self.substeps!r}")
        if not self.stiction_velocity > 0:
            raise ValueError(f"stiction_velocity must be > 0 [rad/s], got {self.stiction_velocity}")


class ArmPlant:
    """The ideal plant (module equation) of ``robot`` over control ticks of ``Ts`` seconds.

    ``q`` and ``v`` [rad, rad/s] read the state (copies) and can be assigned; ``saturated``
    tells whether the last step clipped the torque.
    """

    def __init__(self, robot: Robot, Ts: float, settings: PlantSettings | None = None) -> None:
        self.robot, self.Ts = robot, float(Ts)
        self.settings = settings or PlantSettings()
        S = robot.motor_map
        self._drive = Drive(Chain(robot.model), self.Ts, self.settings.substeps, motor_map=S,
                            gain=1.0, coulomb=robot.coulomb_friction, damping=robot.damping,
                            stiction_ratio=1.0, stribeck_velocity=1.0,
                            smoothing_velocity=self.settings.stiction_velocity, q0=robot.q0,
                            torque_limit=robot.torque_limit, command_map=np.linalg.inv(S).T)
        self._shape = (robot.nv,)
        self.saturated = False

    q = state(0, "Joint angles [rad].")
    v = state(1, "Joint rates [rad/s].")

    def reset(self, q: np.ndarray | None = None, v: np.ndarray | None = None) -> None:
        """Place the arm at ``q`` (default home) with velocity ``v`` (default rest)."""
        self.q = self.robot.check_posture(self.robot.q0 if q is None else q)
        self.v = 0.0 if v is None else v

    def encoders(self) -> np.ndarray:
        """The encoders' joint angles q̃ = Δ·round(q/Δ) [rad] (q without an encoder model)."""
        res = self.robot.encoder_resolution
        return self.q if res is None else res * np.rint(self.q / res)

    def step(self, tau: np.ndarray) -> None:
        """Advance one control tick with ``tau`` [N·m] clipped to ±``torque_limit`` and held."""
        if np.shape(tau) != self._shape:
            raise ValueError(f"tau must have shape {self._shape}, got {np.shape(tau)}")
        self.saturated = self._drive.tick(tau)
