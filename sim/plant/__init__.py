"""The robot the controller drives: torques in, encoder angles out.

================  ================================================================
``kernel``        the one dynamics kernel (``chain.c``): the arm's rigid-body dynamics and
                  its drives integrated over a tick, checked against Pinocchio
``arm``           :class:`ArmPlant`, the ideal plant (torque limits, friction);
                  :class:`PlantSettings`
``hardware``      the hardware-like plant (:class:`HardwareSettings`: I/O delay, DAC, current
                  amplifier, friction with stiction, cables) and the linear plant
================  ================================================================

Every plant has ``encoders()`` (the joint angles the controller reads [rad]), ``step(tau)`` (one
control tick with the torque τ [N·m] held), ``q`` (the joint angles the loop scores) and
``saturated`` (whether the last step clipped the torque).
"""

from __future__ import annotations

from rhmpc.robots import LinearArm, Robot
from rhmpc.sim.plant.arm import ArmPlant, PlantSettings
from rhmpc.sim.plant.hardware import HardwarePlant, HardwareSettings, LinearPlant

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
        return HardwarePlant(robot, Ts, hardware or HardwareSettings())
    return ArmPlant(robot, Ts, settings)
