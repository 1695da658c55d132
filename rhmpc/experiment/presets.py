"""Named operating points (``--preset NAME`` of ``simulate``, ``compare``, ``tune`` and
``config show``).

A preset is a set of dotted settings applied to the run's settings after the defaults and the
``--config`` file, before the explicit options and ``--set``
(:func:`rhmpc.experiment.config.run_config`).

``tuna2013``
    Tuna et al. (T-RO 2013), Table I, their simulation: the plant is "a linearized, reduced
    order model of the actual hardware" (§VIII-B), here the MPC's own linear model
    (``plant.kind = "linear"``), and the effort weight ``mpc.effort_weight = 50`` puts the
    exact-reference run's RMS control effort in the range of Table I(b) (the validation page of
    Tuna et al.'s tables compares the two; ``rhmpc compare --preset tuna2013 --predictors
    exact``). Only the effort weight changes: the paper's horizon (25 ms) and rate (2 kHz) are
    the default controller's. The EKF runs with Tuna's parameters
    (``predictor_params.ekf = "tuna2013"``, §VIII-C), not this package's default. The sensor
    stays the default physical sonomicrometer with causal delivery
    (``--set sensor_settings.playback="offline"`` for the paper's playback of a prerecorded
    file).
``hardware``
    The hardware-like plant: ``[plant]`` with the values of Tuna et al.'s PHANToM rig
    (:data:`HARDWARE_PLANT`, each with its source or stated assumption: one tick of I/O delay,
    12-bit DAC over ±5.5 A, the winding's L/R lag, Coulomb friction from the motors' no-load
    current with a 1.25× stiction peak, rigid cables), cancelled by a controller whose model is
    the published parameter set of Çavuşoğlu et al. 2002 while the arm is the device's
    SolidWorks set (``mismatch.parameters = "phantom-cavusoglu"``) and whose friction model has
    no stiction peak.
``tuna2013-hardware``
    Tuna et al.'s Tables II–III, their experiments on the PHANToM: ``hardware`` with
    ``tuna2013``'s controller weights, the error scored from the forward kinematics of the
    motor encoders' angles, as the paper measured it (§VIII-A: "the actual end-effector
    position calculated from joint angles").
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from rhmpc.errors import UsageError
from rhmpc.sim.plant import PlantSettings

#: The PHANToM rig's plant (``[plant]``), each value's source:
#:
#: - ``delay_ticks`` 1: Tuna et al. give only the 0.5-ms xPC Target period (§VIII); one tick is
#:   what a loop that samples the encoders at the start of a tick and writes the DAC at its end
#:   has (assumption).
#: - ``torque_constant`` 23.4 mN·m/A: the Maxon RE 25 118743 (datasheet).
#: - ``dac_range`` 5.5 A: the motor's stall current at its rated 12 V (datasheet), the most an
#:   amplifier for it delivers; η K_t I_max is then the robot's torque limit (mahilab/Phantom's
#:   rig maps ±10 V to ±1.5 A).
#: - ``dac_bits`` 12: neither SensAble's card nor Tuna's I/O board is named in a source we
#:   found; 12 bits is the coarse end of the boards of that time (assumption).
#: - ``current_time_constant`` L/R = 0.238 mH / 2.18 Ω, the motor's winding (mahilab/Phantom
#:   README.md); a current loop closed around the winding is faster, so this is the slow bound.
#: - ``stiction_ratio`` 1.25 and ``stribeck_velocity`` 10 mrad/s: no published value for this
#:   drive (the identification of Taati et al., Presence 17(4), 2008, was not reachable);
#:   1.0–1.5 is the usual range for brushed motors (assumption).
#: - ``friction_smoothing`` 1 mrad/s: the friction near rest a steep viscous law, the creep of a
#:   residual torque below the stiction peak ≈ v_s τ / F_s.
#: - ``substeps`` 4: h = 125 µs on the elbow's stability bound 2 J v_s / F_s (rigid cables; with
#:   cables the rotor alone on its friction needs 20, ``plant.substeps = 20``).
#: - ``cable_resonance`` 0 (rigid): not published for this device; sweep 40–150 Hz for
#:   sensitivity, do not pick one. ``cable_damping_ratio`` 0.05: light damping of steel cable
#:   drives (assumption).
HARDWARE_PLANT: dict[str, Any] = {
    "plant.kind": "arm", "plant.substeps": 4, "plant.friction_smoothing": 1e-3,
    "plant.delay_ticks": 1, "plant.torque_constant": 0.0234, "plant.dac_range": 5.5,
    "plant.dac_bits": 12, "plant.current_time_constant": 0.238e-3 / 2.18,
    "plant.stiction_ratio": 1.25, "plant.stribeck_velocity": 0.01,
    "plant.cable_resonance": 0.0, "plant.cable_damping_ratio": 0.05, "plant.error_from": "true",
}

#: The ideal arm's plant: every field of ``[plant]`` at its default, every effect off.
IDEAL_PLANT: dict[str, Any] = {f"plant.{f.name}": f.default for f in fields(PlantSettings)}

_TUNA_WEIGHTS = {"mpc.effort_weight": 50.0, "predictor_params.ekf": "tuna2013"}
_HARDWARE = {**HARDWARE_PLANT, "mismatch.parameters": "phantom-cavusoglu"}

#: Preset name → dotted settings it sets.
PRESETS: dict[str, dict[str, Any]] = {
    "tuna2013": {**_TUNA_WEIGHTS, "plant.kind": "linear"},
    "hardware": dict(_HARDWARE),
    "tuna2013-hardware": {**_TUNA_WEIGHTS, **_HARDWARE, "plant.error_from": "encoders"},
}


def preset_settings(name: str | None) -> dict[str, Any]:
    """The dotted settings of preset ``name`` (``None``: none).

    Raises
    ------
    UsageError
        Unknown preset (the message lists the valid ones).
    """
    if name is None:
        return {}
    if name not in PRESETS:
        raise UsageError(f"unknown preset {name!r}; valid: {', '.join(PRESETS)}")
    return dict(PRESETS[name])


def apply_preset(config, name: str | None):
    """``config`` (a :class:`~rhmpc.experiment.config.RunConfig`) with the settings of preset
    ``name`` (:func:`preset_settings`)."""
    return config.replace(**preset_settings(name)) if name is not None else config
