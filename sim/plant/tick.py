"""The robot's side of a control tick: encoders and observer, cancellation, the plant's step.

A tick of the closed loop is::

    x̂ = tick.sense()            encoders q̃ = Δ·round(q/Δ), observer correction
    u = controller.step(x̂, r)   (the controller, outside this module)
    τ = tick.actuate(u)          τ = u + ĝ(q̃) + Ĉ(q̃, q̂̇)q̂̇ + f̂(q̂̇), the controller's model
    tick.advance()               the plant integrates one tick with τ clipped and held; the
                                 observer predicts with the MPC torque that acted

:class:`ArmTick` does it with Pinocchio (:class:`~sim.plant.arm.ArmPlant`), the reference;
:class:`~sim.plant.native.NativeTick` does the same operations compiled. :func:`make_tick`
picks one from :attr:`PlantSettings.dynamics <sim.plant.arm.PlantSettings.dynamics>`, or, by
:attr:`PlantSettings.model <sim.plant.arm.PlantSettings.model>`, the hardware-like plant
(:class:`~sim.plant.hardware.HardwareTick`) or the linear one
(:class:`~sim.plant.hardware.LinearTick`).
"""

from __future__ import annotations

import numpy as np

from robots import LinearArm, Robot
from sim.plant.arm import ArmPlant, PlantSettings
from sim.plant.cancellation import ModelMismatch, NonlinearityCancellation
from sim.plant.hardware import HardwareSettings, HardwareTick, LinearTick
from sim.plant.native import NativeTick
from sim.plant.observer import JointObserver, ObserverSettings


class ArmTick:
    """The robot's side of a tick with Pinocchio's dynamics (see the module docstring).

    Parameters
    ----------
    plant, cancellation, observer
        The plant, the controller's cancellation and its observer, in their initial state.
    encoder_resolution : ndarray or None
        Encoder step Δ per joint [rad]; None: exact joint angles.
    """

    dynamics = "pinocchio"

    def __init__(self, plant: ArmPlant, cancellation: NonlinearityCancellation,
                 observer: JointObserver, encoder_resolution: np.ndarray | None) -> None:
        self.plant, self.cancellation, self.observer = plant, cancellation, observer
        self.dynamics_note = plant.dynamics_note
        self._resolution = encoder_resolution
        self._inv_resolution = None if encoder_resolution is None else 1.0 / encoder_resolution
        self._encoder = np.empty(plant.robot.nv)  # the quantised reading, rewritten every tick
        self._velocity = observer.x[plant.robot.nv :]  # a view of x̂'s q̇ part
        self._q_meas = plant.q
        self._u = self._tau = np.zeros(plant.robot.nv)

    @property
    def q(self) -> np.ndarray:
        """The plant's joint angles [rad] (replaced by every :meth:`advance`)."""
        return self.plant.q

    @property
    def saturated(self) -> bool:
        """Whether the last :meth:`advance` clipped the torque."""
        return self.plant.saturated

    def sense(self) -> np.ndarray:
        """x̂ = [q − q0; q̇] from the encoders (the observer's storage: read, don't keep)."""
        q = self.plant.q
        if self._resolution is not None:  # encoders: q̃ = Δ·round(q/Δ)
            q = np.multiply(q, self._inv_resolution, out=self._encoder)
            np.rint(q, out=q)
            np.multiply(q, self._resolution, out=q)
        self._q_meas = q
        return self.observer.correct(q)

    def actuate(self, u: np.ndarray) -> np.ndarray:
        """The commanded torque τ = u + ĝ + Ĉq̇ + f̂ at the estimate [N·m]."""
        self._u = u
        self._tau = self.cancellation.torque(self._q_meas, self._velocity, u)
        return self._tau

    def advance(self) -> None:
        """Integrate the plant one tick with τ; the observer predicts with the τ_mpc that acted."""
        applied = self.plant.step(self._tau)
        u = self._u
        self.observer.predict(u + (applied - self._tau) if self.plant.saturated else u)


def make_tick(robot: Robot, arm: LinearArm, Ts: float, plant: PlantSettings | None = None,
              mismatch: ModelMismatch | None = None, observer: ObserverSettings | None = None,
              hardware: HardwareSettings | None = None
              ) -> ArmTick | NativeTick | HardwareTick | LinearTick:
    """The robot's side of the loop at the home posture, at rest.

    ``plant.model`` ``"hardware"``: :class:`~sim.plant.hardware.HardwareTick` with
    ``hardware`` (default settings if None); ``"linear"``:
    :class:`~sim.plant.hardware.LinearTick`. The ideal plant: compiled
    (:class:`~sim.plant.native.NativeTick`) when its dynamics are ``"native"`` (``"auto"``
    where the C step builds), else :class:`ArmTick`.
    """
    plant = plant or PlantSettings()
    if plant.model == "linear":
        return LinearTick(robot, arm, JointObserver(arm, robot.encoder_resolution, observer))
    if plant.model == "hardware":
        cancellation = NonlinearityCancellation(robot, mismatch, plant.stiction_velocity)
        return HardwareTick(robot, Ts, hardware or HardwareSettings(), cancellation,
                            JointObserver(arm, robot.encoder_resolution, observer),
                            plant.dynamics)
    arm_plant = ArmPlant(robot, Ts, plant)
    arm_plant.reset()
    cancellation = NonlinearityCancellation(
        robot, mismatch, stiction_velocity=arm_plant.settings.stiction_velocity
    )
    estimator = JointObserver(arm, robot.encoder_resolution, observer)
    if arm_plant.dynamics == "native":
        return NativeTick(arm_plant, cancellation, estimator, robot.encoder_resolution)
    return ArmTick(arm_plant, cancellation, estimator, robot.encoder_resolution)
