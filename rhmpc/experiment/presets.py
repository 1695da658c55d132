"""Named operating points (``--preset NAME`` of ``simulate``, ``compare``, ``tune`` and
``config show``).

A preset is a set of dotted settings applied to the run's settings after the defaults and the
``--config`` file, before the explicit options and ``--set``
(:func:`rhmpc.experiment.config.run_config`).

``tuna2013``
    Tuna et al. (T-RO 2013), Table I, their simulation: the plant is "a linearized, reduced
    order model of the actual hardware" (§VIII-B), here the MPC's own linear model
    (``plant.model = "linear"``), and the effort weight ``mpc.effort_weight = 50`` puts the
    exact-reference run's RMS control effort in the range of Table I(b) (the validation page of
    Tuna et al.'s tables compares the two; ``rhmpc compare --preset tuna2013 --predictors
    exact``). Only the effort weight changes: the paper's horizon (25 ms) and rate (2 kHz) are
    the default controller's. The EKF runs with Tuna's parameters
    (``predictor_params.ekf = "tuna2013"``, §VIII-C), not this package's default. The sensor
    stays the default physical sonomicrometer with causal delivery
    (``--set sensor_settings.playback="offline"`` for the paper's playback of a prerecorded
    file).
``hardware``
    The hardware-like plant (:mod:`rhmpc.sim.plant.hardware`, every default with its source or
    stated assumption: one tick of I/O delay, 12-bit DAC over ±5.5 A, the winding's L/R lag,
    Coulomb friction from the motors' no-load current with a 1.25× stiction peak, rigid
    cables), cancelled by a controller whose model is the published parameter set of
    Çavuşoğlu et al. 2002 while the arm is the device's SolidWorks set
    (``mismatch.parameters = "phantom-cavusoglu"``) and whose friction model has no stiction
    peak.
``tuna2013-hardware``
    Tuna et al.'s Tables II–III, their experiments on the PHANToM: ``hardware`` with
    ``tuna2013``'s controller weights, the error scored from the forward kinematics of the
    motor encoders' angles, as the paper measured it (§VIII-A: "the actual end-effector
    position calculated from joint angles").
"""

from __future__ import annotations

from typing import Any

from rhmpc.errors import UsageError

_TUNA_WEIGHTS = {"mpc.effort_weight": 50.0, "predictor_params.ekf": "tuna2013"}
_HARDWARE = {"plant.model": "hardware", "mismatch.parameters": "phantom-cavusoglu"}

#: Preset name → dotted settings it sets.
PRESETS: dict[str, dict[str, Any]] = {
    "tuna2013": {**_TUNA_WEIGHTS, "plant.model": "linear"},
    "hardware": dict(_HARDWARE),
    "tuna2013-hardware": {**_TUNA_WEIGHTS, **_HARDWARE, "hardware.error_from": "encoders"},
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
