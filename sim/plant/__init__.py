"""The robot the controller drives: its dynamics, the controller's cancellation, the observer.

================  ================================================================
``arm``           :class:`ArmPlant`: Pinocchio's forward dynamics (ABA) integrated over a
                  tick, torque limits, friction; :class:`PlantSettings`
``cancellation``  :class:`NonlinearityCancellation` ĝ + Ĉq̇ + f̂ from the controller's own
                  model; :class:`ModelMismatch`
``observer``      :class:`JointObserver`: x̂ = [q − q0; q̇] from quantised encoders
``hardware``      the hardware-like plant (:class:`HardwareSettings`: I/O delay, DAC, current
                  amplifier, friction with stiction, cables) and the linear plant
``native``        the same tick compiled (an accelerator, checked against Pinocchio)
================  ================================================================
"""

from sim.plant.arm import ArmPlant, PlantSettings
from sim.plant.cancellation import ModelMismatch, NonlinearityCancellation
from sim.plant.hardware import HardwareSettings
from sim.plant.observer import JointObserver, ObserverSettings

__all__ = [
    "ArmPlant", "HardwareSettings", "JointObserver", "ModelMismatch", "NonlinearityCancellation",
    "ObserverSettings", "PlantSettings",
]
