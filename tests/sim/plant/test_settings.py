"""The one ``[plant]`` table: each effect's neutral value is the ideal arm's, the integration's
rule, and the hardware preset's values."""

import dataclasses
import math

import numpy as np
import pytest

from rhmpc.sim.plant import ArmPlant, HardwarePlant, LinearPlant, PlantSettings, make_plant
from rhmpc.sim.plant.settings import EFFECTS, friction_step, integration_steps
from tests.sim.plant import rig

TS = 0.5e-3
#: Each effect switched on, with what it needs.
ON = {"delay_ticks": {"delay_ticks": 1},
      "torque_constant": {"torque_constant": 0.0234, "dac_range": 5.5},
      "current_time_constant": {"torque_constant": 0.0234, "dac_range": 5.5,
                                "current_time_constant": 1e-4},
      "dac_bits": {"torque_constant": 0.0234, "dac_range": 5.5, "dac_bits": 12},
      "stiction_ratio": {"stiction_ratio": 1.25},
      "cable_resonance": {"cable_resonance": 80.0, "substeps": 40},
      "error_from": {"error_from": "encoders"}}


def test_every_effect_is_off_by_default_and_the_plant_is_the_ideal_arm(phantom, arm):
    settings = PlantSettings()
    assert settings.effects == () and settings.label == "ideal"
    assert isinstance(make_plant(phantom, arm, TS, settings), ArmPlant)
    assert isinstance(make_plant(phantom, arm, TS, PlantSettings(kind="linear")), LinearPlant)
    assert set(ON) == set(EFFECTS)


@pytest.mark.parametrize("effect", EFFECTS)
def test_one_effect_on_makes_the_hardware_like_plant(phantom, arm, effect):
    settings = PlantSettings(**ON[effect])
    assert effect in settings.effects and settings.label == "hardware"
    assert isinstance(make_plant(phantom, arm, TS, settings), HardwarePlant)


def test_the_drive_with_every_effect_at_its_neutral_value_is_the_ideal_arm(phantom):
    """The hardware-like plant's equations with every effect neutral integrate the ideal arm's:
    the same joint angles and rates over 200 ticks of random torques, to 1e-12."""
    ideal, drive = ArmPlant(phantom, TS), HardwarePlant(phantom, TS, PlantSettings())
    rng = np.random.default_rng(5)
    for tau in rng.uniform(-2.0, 2.0, (200, 3)):  # beyond the limits: both clip
        ideal.step(tau)
        drive.step(tau)
        assert ideal.saturated == drive.saturated
    np.testing.assert_allclose(drive.q_arm, ideal.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(drive.v, ideal.v, rtol=0, atol=1e-12)


def test_the_hardware_preset_holds_the_rigs_values():
    s = rig()
    assert (s.kind, s.substeps, s.friction_smoothing, s.delay_ticks) == ("arm", 4, 1e-3, 1)
    assert (s.torque_constant, s.dac_range, s.dac_bits) == (0.0234, 5.5, 12)
    assert s.current_time_constant == 0.238e-3 / 2.18  # L/R of the Maxon RE 25 118743
    assert (s.stiction_ratio, s.stribeck_velocity) == (1.25, 0.01)
    assert (s.cable_resonance, s.cable_damping_ratio, s.error_from) == (0.0, 0.05, "true")
    assert s.effects == ("delay_ticks", "torque_constant", "current_time_constant", "dac_bits",
                         "stiction_ratio")


def test_integration_steps_follow_the_friction_stiffness(phantom):
    """h_f = J v_s / F_s by hand for one motor; the automatic count max(2, ⌈Ts / h_f⌉); an
    explicit count below ⌈Ts / (2 h_f)⌉ is refused, naming the automatic one."""
    J, F = np.array([1e-3, 2e-3]), np.array([0.01, 0.005])
    s = PlantSettings(friction_smoothing=1e-3, stiction_ratio=1.25)
    h = 1e-3 * 1e-3 / (1.25 * 0.01)
    assert friction_step(s, J, F) == pytest.approx(h, rel=1e-15)
    automatic = integration_steps(dataclasses.replace(s, substeps=0), TS, J, F)
    assert automatic == math.ceil(TS / h) == 7
    assert integration_steps(dataclasses.replace(s, substeps=4), TS, J, F) == 4
    with pytest.raises(ValueError, match=r"stability bound \(4 .*>= 4, or 0 \(automatic: 7\)"):
        integration_steps(dataclasses.replace(s, substeps=3), TS, J, F)
    assert integration_steps(PlantSettings(substeps=0), TS, J, np.zeros(2)) == 2


def test_the_published_counts_are_within_the_stability_bound(phantom, arm):
    """The ideal arm's 2 steps and the rig's 4 (20 with cables) pass; the rig with cables at
    its rigid count is refused."""
    for settings in (PlantSettings(), rig(), rig(cable_resonance=80.0, substeps=20)):
        make_plant(phantom, arm, TS, settings)
    assert isinstance(make_plant(phantom, arm, TS, PlantSettings(substeps=0)), ArmPlant)
    with pytest.raises(ValueError, match=r"plant\.substeps >= 17, or 0"):
        make_plant(phantom, arm, TS, rig(cable_resonance=80.0))
