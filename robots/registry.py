"""`load_robot(name)`: the robots this project knows, by name."""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources

import numpy as np
import pinocchio as pin

from robots.model import Robot

#: PHANToM Premium 1.5A actuator data (Cavusoglu et al. 2002; see the URDF header).
PHANTOM_GEAR_RATIO = np.array([13.3, 11.2, 11.2])
PHANTOM_MOTOR_PEAK_TORQUE = 0.129  # [N·m]
PHANTOM_MOTOR_NOMINAL_TORQUE = 0.0286  # [N·m]
PHANTOM_ROTOR_INERTIA = 1.08e-6  # [kg·m²]
PHANTOM_ENCODER_COUNTS = 4 * 1024  # counts per motor revolution (1024 lines, x4 quadrature)


def urdf_path(filename: str) -> str:
    """Path of a URDF shipped in ``robots/urdf`` (works from an installed wheel too)."""
    ref = resources.files("robots") / "urdf" / filename
    if not ref.is_file():
        raise FileNotFoundError(f"robot description {filename!r} is not installed with 'robots'")
    return str(ref)


def _phantom() -> Robot:
    model = pin.buildModelFromUrdf(urdf_path("phantom_premium_1_5a.urdf"))
    model.armature[:] = PHANTOM_GEAR_RATIO**2 * PHANTOM_ROTOR_INERTIA
    return Robot(
        name="phantom",
        model=model,
        ee_frame="tip",
        q0=np.array([0.0, 0.0, np.pi / 2]),
        torque_limit=PHANTOM_GEAR_RATIO * PHANTOM_MOTOR_PEAK_TORQUE,
        encoder_resolution=2 * np.pi / (PHANTOM_ENCODER_COUNTS * PHANTOM_GEAR_RATIO),
        description="PHANToM Premium 1.5A, serial 3-DOF equivalent (shipped URDF)",
    )


def _finger_edu() -> Robot:
    import example_robot_data

    model = example_robot_data.load("finger_edu").model
    # The URDF's effort limit (1000 N·m) is a placeholder; the TriFinger motors saturate at
    # 0.36 N·m at the joint (Wüthrich et al., "TriFinger", CoRL 2020). The URDF has no armature,
    # damping or friction: they stay zero.
    torque_limit = np.full(model.nv, 0.36)
    model.effortLimit[:] = torque_limit
    return Robot(
        name="finger_edu",
        model=model,
        ee_frame="finger_tip_link",
        q0=np.array([0.0, 0.6, -1.2]),
        torque_limit=torque_limit,
        encoder_resolution=None,
        description="TriFinger Edu finger from example-robot-data (loaders)",
    )


#: UR5 wrist posture locked by the reduction [rad] (wrist_1, wrist_2, wrist_3): tool pointing down.
UR5_LOCKED_WRIST = np.array([-np.pi / 2, -np.pi / 2, 0.0])


def _ur5() -> Robot:
    import example_robot_data

    full = example_robot_data.load("ur5").model
    q_ref = pin.neutral(full)
    wrist = [full.getJointId(n) for n in ("wrist_1_joint", "wrist_2_joint", "wrist_3_joint")]
    for jid, value in zip(wrist, UR5_LOCKED_WRIST, strict=True):
        q_ref[full.joints[jid].idx_q] = value
    model = pin.buildReducedModel(full, wrist, q_ref)
    return Robot(
        name="ur5",
        model=model,
        ee_frame="tool0",
        q0=np.array([0.0, -np.pi / 3, np.pi / 2]),
        torque_limit=np.asarray(model.effortLimit).copy(),
        encoder_resolution=None,
        description="UR5 from example-robot-data, first three joints (wrist locked at "
        "(-90, -90, 0) deg)",
    )


_FACTORIES: dict[str, Callable[[], Robot]] = {
    "phantom": _phantom,
    "finger_edu": _finger_edu,
    "ur5": _ur5,
}

#: Registered robot names.
ROBOTS: tuple[str, ...] = tuple(_FACTORIES)


def load_robot(name: str) -> Robot:
    """Build a registered robot.

    Raises
    ------
    ValueError
        If ``name`` is not registered; the message lists the valid names.
    """
    try:
        factory = _FACTORIES[name]
    except KeyError:
        raise ValueError(f"unknown robot {name!r}; valid robots: {', '.join(ROBOTS)}") from None
    return factory()
