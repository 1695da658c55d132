"""The robot the controller drives: torques in, encoder angles out.

================  ================================================================
``arm``           :class:`ArmPlant`: Pinocchio's forward dynamics integrated over a tick,
                  torque limits, friction; :class:`PlantSettings`
``hardware``      the hardware-like plant (:class:`HardwareSettings`: I/O delay, DAC, current
                  amplifier, friction with stiction, cables) and the linear plant
``native``        the plant's dynamics compiled (the one dynamics kernel, checked against
                  Pinocchio)
================  ================================================================

Every plant has ``encoders()`` (the joint angles the controller reads [rad]), ``step(tau)`` (one
control tick with the torque τ [N·m] held), ``q`` (the joint angles the loop scores) and
``saturated`` (whether the last step clipped the torque).
"""

from __future__ import annotations

from robots import LinearArm, Robot
from sim.plant.arm import ArmPlant, PlantSettings
from sim.plant.hardware import HardwarePlant, HardwareSettings, LinearPlant

__all__ = ["ArmPlant", "HardwarePlant", "HardwareSettings", "LinearPlant", "PlantSettings",
           "make_plant"]


def make_plant(robot: Robot, arm: LinearArm, Ts: float, settings: PlantSettings | None = None,
               hardware: HardwareSettings | None = None) -> ArmPlant | HardwarePlant | LinearPlant:
    """The plant of ``settings.model`` at the home posture, at rest: ``"ideal"`` (the nonlinear
    arm, :class:`ArmPlant`), ``"hardware"`` (:class:`HardwarePlant` with ``hardware``, default
    settings if None) or ``"linear"`` (the MPC's own model, :class:`LinearPlant`)."""
    settings = settings or PlantSettings()
    if settings.model == "linear":
        return LinearPlant(robot, arm)
    if settings.model == "hardware":
        return HardwarePlant(robot, Ts, hardware or HardwareSettings(), settings.dynamics)
    plant = ArmPlant(robot, Ts, settings)
    plant.reset()
    return plant
