"""Tests of the plants; :func:`rig` is the hardware preset's plant."""

from dataclasses import replace

from rhmpc.experiment.presets import HARDWARE_PLANT
from rhmpc.sim.plant import PlantSettings


def rig(**changes) -> PlantSettings:
    """The plant of Tuna's PHANToM rig (``--preset hardware``), with ``changes``."""
    settings = PlantSettings(**{k.removeprefix("plant."): v for k, v in HARDWARE_PLANT.items()})
    return replace(settings, **changes)
