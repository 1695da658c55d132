"""The robot the controller drives: torques in, encoder angles out.

================  ================================================================
``settings``      :class:`PlantSettings` (``[plant]``): the plant's kind, its integration and
                  each hardware effect as an option, off at its neutral value
``kernel``        the one dynamics kernel (``chain.c``): the arm's rigid-body dynamics and
                  its drives integrated over a tick, checked against Pinocchio
``arm``           :class:`ArmPlant`, the ideal plant (torque limits, friction): every effect off
``hardware``      the hardware-like plant (:class:`HardwarePlant`: I/O delay, DAC, current
                  amplifier, friction with stiction, cables) and the linear plant
================  ================================================================

Every plant has ``encoders()`` (the joint angles the controller reads [rad]), ``step(tau)`` (one
control tick with the torque τ [N·m] held), ``q`` (the joint angles the loop scores) and
``saturated`` (whether the last step clipped the torque).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from rhmpc.sim.plant.settings import PlantSettings

if TYPE_CHECKING:
    from rhmpc.robots import LinearArm, Robot
    from rhmpc.sim.plant.arm import ArmPlant
    from rhmpc.sim.plant.hardware import HardwarePlant, LinearPlant

#: The plants and their modules, loaded when first asked for: the settings alone (the presets,
#: the command line's parsers) load neither Pinocchio nor the kernel.
_EXPORTS = {"ArmPlant": "arm", "HardwarePlant": "hardware", "LinearPlant": "hardware"}

__all__ = ["ArmPlant", "HardwarePlant", "LinearPlant", "PlantSettings", "make_plant"]


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)


def make_plant(robot: Robot, arm: LinearArm, Ts: float, settings: PlantSettings | None = None,
               ) -> ArmPlant | HardwarePlant | LinearPlant:
    """The plant of ``settings`` at the home posture, at rest: the MPC's own model
    (:class:`LinearPlant`) for ``kind = "linear"``; else the arm, :class:`ArmPlant` with every
    effect at its neutral value (the ideal plant) or :class:`HardwarePlant` with some on."""
    from rhmpc.sim.plant.arm import ArmPlant
    from rhmpc.sim.plant.hardware import HardwarePlant, LinearPlant

    settings = settings or PlantSettings()
    if settings.kind == "linear":
        return LinearPlant(robot, arm)
    if settings.effects:
        return HardwarePlant(robot, Ts, settings)
    return ArmPlant(robot, Ts, settings)
