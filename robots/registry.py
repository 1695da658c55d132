"""`load_robot(name)`: the robots this project knows, by name."""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources

import numpy as np
import pinocchio as pin

from robots.model import Robot

#: PHANToM Premium 1.5A drive data. Transmission ratios: mahilab/Phantom
#: cpp/src/PhantomModel.hpp ``Eta``. Motor Maxon RE 25 118743 (mahilab/Phantom README.md, the
#: Maxon datasheet's values): stall torque 129 mN·m, nominal 28.6 mN·m, rotor inertia 10.3 g·cm²
#: (PhantomModel.hpp uses 1.08e-6 kg·m², 5 % more), torque constant 23.4 mN·m/A, no-load current
#: 26.3 mA, terminal resistance 2.18 Ω and inductance 0.238 mH. Encoder HEDM-5500, 1024 cycles
#: per turn decoded ×4 (README.md; PhantomHardware.hpp ``QuadMode::X4``) on the motor shafts.
PHANTOM_GEAR_RATIO = np.array([13.3, 11.2, 11.2])
PHANTOM_MOTOR_PEAK_TORQUE = 0.129  # [N·m]
PHANTOM_MOTOR_NOMINAL_TORQUE = 0.0286  # [N·m]
PHANTOM_ROTOR_INERTIA = 1.03e-6  # [kg·m²]
PHANTOM_TORQUE_CONSTANT = 0.0234  # [N·m/A]
PHANTOM_NO_LOAD_CURRENT = 0.0263  # [A]
PHANTOM_WINDING_RESISTANCE = 2.18  # [Ω]
PHANTOM_WINDING_INDUCTANCE = 0.238e-3  # [H]
PHANTOM_ENCODER_COUNTS = 4 * 1024  # counts per motor revolution (1024 lines, x4 quadrature)
#: The motors' output angles from the model's joints: yaw q1; the shoulder drum turns with the
#: upper arm, q2_src = −q2; the elbow drum with the forearm's absolute angle, q3_src = −(q2 + q3)
#: about home (PhantomModel.cpp forward_kinematics: q3_src = 90° − (q2 + q3)).
PHANTOM_MOTOR_MAP = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, -1.0, -1.0]])
#: The forearm's absolute limit −29° ≤ q3_src ≤ 214° (PhantomModel.hpp Q_min, Q_max) as a
#: coupling of the model's joints: −124° ≤ q2 + q3 ≤ 119°.
PHANTOM_COUPLING = ((np.array([0.0, 1.0, 1.0]), np.radians(-124.0), np.radians(119.0)),)
#: Standard gravity of the source's model (PhantomModel.hpp ``g``) [m/s²].
STANDARD_GRAVITY = 9.80665


def urdf_path(filename: str) -> str:
    """Path of a URDF shipped in ``robots/urdf`` (works from an installed wheel too)."""
    ref = resources.files("robots") / "urdf" / filename
    if not ref.is_file():
        raise FileNotFoundError(f"robot description {filename!r} is not installed with 'robots'")
    return str(ref)


def phantom_friction() -> np.ndarray:
    """Coulomb friction of each drive on its output coordinate, K_t·I₀·η [N·m].

    The datasheet's no-load current I₀ is the current that overcomes the motor's own brush and
    bearing friction: K_t I₀ = 0.615 mN·m at the motor, ``(8.19, 6.89, 6.89)`` mN·m through the
    transmissions. No viscous term is sourced: the whole no-load loss is taken as Coulomb.
    """
    return PHANTOM_TORQUE_CONSTANT * PHANTOM_NO_LOAD_CURRENT * PHANTOM_GEAR_RATIO


def _add_rotor(model: pin.Model, joint: str, inertia: float) -> None:
    """Add a rotor's reflected inertia about the pitch axis (y) to the body of ``joint``."""
    jid = model.getJointId(joint)
    model.inertias[jid] = model.inertias[jid] + pin.Inertia(
        0.0, np.zeros(3), np.diag([0.0, inertia, 0.0]))


def _phantom_from(filename: str, name: str, description: str) -> Robot:
    """The PHANToM from a tree-with-mimic URDF plus its drives (module constants).

    The reflected rotor inertia η²J_m of each motor acts on that motor's output angle: the yaw
    motor's on q1 (``armature``), the shoulder motor's on q2 (``armature``), the elbow motor's
    on the forearm's absolute angle q2 + q3, so it is put on the crank body ``drive_link``,
    which turns with that angle about the shoulder axis. The model's M(q) then holds
    ``Sᵀ diag(η²J_m) S`` (S the motor map): the armature block [[a2 + a3, a3], [a3, a3]] on
    (q2, q3), which a diagonal armature cannot hold.
    """
    model = pin.buildModelFromUrdf(urdf_path(filename), mimic=True)
    model.gravity.linear[:] = [0.0, 0.0, -STANDARD_GRAVITY]
    rotor = PHANTOM_GEAR_RATIO**2 * PHANTOM_ROTOR_INERTIA
    model.armature[:] = [rotor[0], rotor[1], 0.0]
    _add_rotor(model, "elbow_drive", rotor[2])
    model.friction[:] = phantom_friction()
    model.damping[:] = 0.0
    return Robot(
        name=name,
        model=model,
        ee_frame="tip",
        q0=np.array([0.0, 0.0, np.pi / 2]),
        torque_limit=PHANTOM_GEAR_RATIO * PHANTOM_MOTOR_PEAK_TORQUE,
        encoder_resolution=2 * np.pi / (PHANTOM_ENCODER_COUNTS * PHANTOM_GEAR_RATIO),
        description=description,
        motor_map=PHANTOM_MOTOR_MAP,
        gear_ratio=PHANTOM_GEAR_RATIO,
        rotor_inertia=rotor,
        coupling=PHANTOM_COUPLING,
    )


def _phantom() -> Robot:
    return _phantom_from("phantom_premium_1_5a.urdf", "phantom",
                         "PHANToM Premium 1.5A, parallelogram as a tree with mimic joints "
                         "(SolidWorks mass properties, mahilab/Phantom)")


def _phantom_cavusoglu() -> Robot:
    return _phantom_from("phantom_premium_1_5a_cavusoglu.urdf", "phantom-cavusoglu",
                         "PHANToM Premium 1.5A with the mass properties of Cavusoglu et al. "
                         "2002 (mahilab/Phantom transcription)")


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
    "phantom-cavusoglu": _phantom_cavusoglu,
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
