"""A robot from its file: a URDF, the three joints the controller drives, the tool and the home.

A robot file is TOML. Its keys (SI units; angles in radians)::

    urdf = "panda.urdf"                   # relative to this file, absolute, or
                                          # package://NAME/PATH (example-robot-data's robots,
                                          # then $ROS_PACKAGE_PATH)
    joints = ["j1", "j2", "j4"]           # the three actuated joints, in order
    locked = { j3 = 0.0, j5 = 0.0 }       # every other joint stays at its value here, or at
                                          # its neutral value where named nowhere
    tool_frame = "tcp"                    # the controlled point: a frame's origin, or
    tool = { frame = "link8", point = [0.0, 0.0, 0.1] }   # a point [m] on a frame
    home = [0.0, 0.3, -1.8]               # the home posture (the MPC's linearisation point)
    # optional
    name = "panda"                        # default: the file's name without .toml
    description = "one line"
    torque_limits = [87.0, 87.0, 87.0]    # [N·m]; default: the URDF's effort limits
    armature = [0.0, 0.0, 0.0]            # reflected rotor inertia [kg·m²]; default 0
    friction = [0.0, 0.0, 0.0]            # Coulomb [N·m]; default: the URDF's <dynamics>
    damping = [0.0, 0.0, 0.0]             # viscous [N·m·s/rad]; default: the URDF's <dynamics>
    encoder_resolution = [1e-5, 1e-5, 1e-5]   # [rad per count]; default: no encoder model
    gravity = 9.81                        # [m/s²] along the world's −z; default Pinocchio's
    workspace = 0.01                      # half-width of the cube about the tool's home that
                                          # the POI may visit [m] (default 10 mm)
    motor_map = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]    # θ = S (q − q0): see rhmpc.robots.Robot
    coupling = [{ row = [0, 1, 1], lower = -2.16, upper = 2.08 }]   # lower ≤ row·q ≤ upper
    inconsistent_inertia = ["upper_arm"]  # links whose published inertia breaks the triangle
                                          # inequality, kept as published
    [drives]                              # geared motors, all keys together: they give the
    gear_ratio = [13.3, 11.2, 11.2]       # torque limits η·peak_torque, the friction
    peak_torque = 0.129                   # K_t·I₀·η, the reflected inertias η²·J_m and the
    torque_constant = 0.0234              # encoders' 2π/(counts·η) where the keys above do
    no_load_current = 0.0263              # not give them
    rotor_inertia = 1.03e-6
    encoder_counts = 4096
    rotor_joints = ["j1", "j2", "j3"]     # the joint turning with each motor's output angle
                                          # (default: the actuated joints)

Everything is checked before a robot is built: the URDF's size and physics before a native
parser reads it (:mod:`rhmpc.robots.urdf_reader`), every number a number (not a boolean, not
text), the names exist, the limits are sane, the home posture lies within the joint limits and
away from a singularity, the arm holds it against gravity within its torque limits, and the
tool reaches the cube of ``workspace`` about its home position. A problem raises
:class:`RobotFileError`, one line naming the file and the key.

The default ``workspace`` is half the mitral annulus's total travel of about 20 mm (Yuen et al.,
IJRR 2009, §2), the largest heart motion of the sources.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np
import pinocchio as pin

from rhmpc.io import FileError, read_text, read_toml
from rhmpc.robots.checks import (
    RobotFileError,
    check_home,
    floats,
    is_number,
    listed,
    number,
    vector,
)
from rhmpc.robots.model import Robot
from rhmpc.robots.urdf_reader import UrdfError, read_model

#: Keys of a robot file and of its [drives] table.
KEYS = ("urdf", "joints", "locked", "tool_frame", "tool", "home", "name", "description",
        "torque_limits", "armature", "friction", "damping", "encoder_resolution", "gravity",
        "workspace", "motor_map", "coupling", "inconsistent_inertia", "drives")
DRIVE_KEYS = ("gear_ratio", "peak_torque", "torque_constant", "no_load_current",
              "rotor_inertia", "encoder_counts", "rotor_joints")
#: The POI's reach about the tool's home position by default [m] (Yuen et al. 2009, §2).
WORKSPACE = 0.01
#: The largest URDF read [bytes] (the robot file is a settings file: ``rhmpc.io``'s bound).
MAX_URDF_BYTES = 2**26
#: The farthest a tool's point may lie from its frame [m]: no arm that reaches a patient's
#: heart is larger; a point beyond it is a unit error (millimetres written as metres).
MAX_TOOL_OFFSET = 10.0
#: Revolute joints the controller can drive (one angle each).
_REVOLUTE = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned")
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


def _read_urdf(path: Path) -> str:
    """The URDF's text through the one guarded reader (a regular file of bounded size)."""
    try:
        return read_text(path, "file", MAX_URDF_BYTES)
    except FileError as exc:
        raise RobotFileError(f"urdf: {exc}") from None


def _package(url: str) -> Path:
    """``package://NAME/PATH``: NAME in example-robot-data's robots, then in $ROS_PACKAGE_PATH."""
    relative = url[len("package://"):]
    roots = [d for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
    try:
        from example_robot_data.robots_loader import getModelPath

        roots.insert(0, getModelPath(relative))
    except (ImportError, OSError):
        pass
    for root in roots:
        if (Path(root) / relative).is_file():
            return Path(root) / relative
    raise RobotFileError(f"urdf: {url} is neither in example-robot-data's robots nor in "
                         "$ROS_PACKAGE_PATH")


def read_file(path: str | Path) -> dict:
    """The robot file's table (:func:`rhmpc.io.read_toml`: a file that cannot be read, or is
    not TOML, is a ``FileError`` naming it); unknown or missing keys raise
    :class:`RobotFileError`."""
    if Path(path).suffix.lower() in (".urdf", ".xacro", ".xml"):
        raise RobotFileError(f"a robot file (TOML) is expected, not a URDF: write one that "
                             f"names it, urdf = \"{Path(path).name}\", with joints, tool_frame "
                             "and home (docs: guide/your-robot)")
    try:
        doc = read_toml(path)
    except FileError as exc:  # naming the file
        if "not valid TOML" not in str(exc):
            raise
        raise FileError(f"{exc}; a robot file is TOML: urdf = \"arm.urdf\", joints = [...], "
                        "tool_frame and home (docs: guide/your-robot)") from None
    unknown = sorted(set(doc) - set(KEYS))
    if unknown:
        raise RobotFileError(f"{unknown[0]}: unknown key; valid keys: {', '.join(KEYS)}")
    for key in ("urdf", "joints", "home"):
        if key not in doc:
            raise RobotFileError(f"{key}: missing")
    if "tool_frame" in doc and "tool" in doc:
        raise RobotFileError("tool_frame: give the tool as tool_frame = \"FRAME\" or as tool = "
                             "{ frame = \"FRAME\", point = [x, y, z] }, not both")
    return doc


def _urdf_path(doc: dict, base: Path) -> Path:
    url = doc["urdf"]
    if not isinstance(url, str) or not url:
        raise RobotFileError(f"urdf: must be a file name, got {url!r}")
    return _package(url) if url.startswith("package://") else base / url


def _full_model(doc: dict, path: Path) -> pin.Model:
    """The URDF's model (mimic joints follow their joints), read without its meshes once its
    size and physics passed :func:`rhmpc.robots.urdf_reader.check_urdf`."""
    unchecked = doc.get("inconsistent_inertia", [])
    if not isinstance(unchecked, list) or not all(isinstance(n, str) for n in unchecked):
        raise RobotFileError(f"inconsistent_inertia: must be a list of link names, got "
                             f"{unchecked!r}")
    try:
        model = read_model(_read_urdf(path), frozenset(unchecked))
    except UrdfError as exc:
        raise RobotFileError(f"urdf: {path}: {exc}") from None
    for name in unchecked:
        if not model.existBodyName(name):
            raise RobotFileError(f"inconsistent_inertia: no link {name!r} in {path.name}")
    return model


def _joint(full: pin.Model, name, key: str, urdf: Path) -> int:
    """The id of the one-angle revolute joint ``name``."""
    if not isinstance(name, str) or not full.existJointName(name):
        names = ", ".join(n for n, j in zip(full.names[1:], full.joints[1:], strict=True)
                          if j.nq == 1)
        raise RobotFileError(f"{key}: no joint {name!r} in {urdf.name} (its joints: {names})")
    jid = full.getJointId(name)
    if full.joints[jid].shortname() not in _REVOLUTE:
        raise RobotFileError(f"{key}: joint {name!r} is {full.joints[jid].shortname()}, not a "
                             "revolute joint with limits")
    return jid


def _reduced(doc: dict, full: pin.Model, urdf: Path) -> pin.Model:
    """The model of the three actuated joints, every other joint locked."""
    joints = doc["joints"]
    if not isinstance(joints, list) or len(joints) != 3 or len(set(map(str, joints))) != 3:
        raise RobotFileError(f"joints: must name 3 distinct joints, got {joints!r}")
    actuated = [_joint(full, name, "joints", urdf) for name in joints]
    locked = doc.get("locked", {})
    if not isinstance(locked, dict):
        raise RobotFileError(f"locked: must be a table of joint = angle, got {locked!r}")
    q_ref = pin.neutral(full)
    for name, value in locked.items():
        jid = _joint(full, name, "locked", urdf)
        if jid in actuated:
            raise RobotFileError(f"locked: joint {name!r} is also actuated (joints)")
        idx = full.joints[jid].idx_q
        lo, hi = full.lowerPositionLimit[idx], full.upperPositionLimit[idx]
        if not is_number(value):
            raise RobotFileError(f"locked: {name} = {value!r} must be an angle [rad]")
        if not lo - 1e-9 <= value <= hi + 1e-9:
            raise RobotFileError(f"locked: {name} = {value!r} is outside its limits "
                                 f"[{lo:.4g}, {hi:.4g}] rad")
        q_ref[idx] = float(value)
    lock = [j for j in range(1, full.njoints) if full.joints[j].nq > 0 and j not in actuated]
    held = {full.joints[j].idx_q for j in lock}  # a mimic joint shares its joint's idx_q
    lock += [j for j in range(1, full.njoints) if full.joints[j].nq == 0
             and full.joints[j].idx_q in held]
    model = pin.buildReducedModel(full, lock, q_ref) if lock else full.copy()
    order = [model.getJointId(name) for name in joints]
    if order != sorted(order):
        raise RobotFileError(f"joints: list them in the URDF's order from the base, "
                             f"{[model.names[j] for j in sorted(order)]}")
    return model


def _tool(doc: dict, model: pin.Model) -> str:
    """The tool's frame name (a frame added at ``tool.point`` for a point on a frame)."""
    if "tool_frame" not in doc and "tool" not in doc:  # said once the frames are known
        raise RobotFileError("tool_frame: missing; name the controlled point's frame, "
                             f"tool_frame = \"FRAME\" (the URDF's frames: {_frames(model)}), "
                             "or a point on one, tool = { frame = \"FRAME\", point = [x, y, z] }")
    if "tool_frame" in doc:
        frame = doc["tool_frame"]
        _frame(model, frame, "tool_frame")
        return frame
    tool = doc["tool"]
    if not isinstance(tool, dict) or set(tool) != {"frame", "point"}:
        raise RobotFileError(f"tool: must be {{ frame = \"FRAME\", point = [x, y, z] }}, got "
                             f"{tool!r}")
    _frame(model, tool["frame"], "tool.frame")
    point = vector(tool, "point", 3)
    if np.linalg.norm(point) > MAX_TOOL_OFFSET:
        raise RobotFileError(f"tool.point: {np.linalg.norm(point):.4g} m from frame "
                             f"{tool['frame']!r}; a tool's point lies within "
                             f"{MAX_TOOL_OFFSET:g} m of its frame (metres, not millimetres)")
    parent = model.frames[model.getFrameId(tool["frame"])]
    placement = parent.placement * pin.SE3(np.eye(3), point)
    model.addFrame(pin.Frame("tool", parent.parentJoint, model.getFrameId(tool["frame"]),
                             placement, pin.FrameType.OP_FRAME))
    return "tool"


def _frame(model: pin.Model, frame, key: str) -> None:
    """``frame`` names a frame of the model; else the message lists them (the first 40)."""
    if isinstance(frame, str) and model.existFrame(frame):
        return
    raise RobotFileError(f"{key}: no frame {frame!r} in the URDF (its frames: {_frames(model)})")


def _frames(model: pin.Model) -> str:
    """The model's frame names, the first 40 of them."""
    names = [f.name for f in model.frames if f.name != "universe"]
    return ", ".join(names[:40]) + (f", … ({len(names)} in all)" if len(names) > 40 else "")


def _check_limits(model: pin.Model) -> None:
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for j in range(3):
        name = model.names[j + 1]
        if not (np.isfinite(lower[j]) and np.isfinite(upper[j]) and lower[j] < upper[j]):
            raise RobotFileError(f"joints: joint {name!r} has no sane position limits in the "
                                 f"URDF ([{lower[j]:g}, {upper[j]:g}] rad)")
        if not (np.isfinite(model.velocityLimit[j]) and model.velocityLimit[j] > 0):
            raise RobotFileError(f"joints: joint {name!r} has no velocity limit > 0 in the URDF")


def _drives(doc: dict, model: pin.Model, joints: list[str]) -> dict:
    """What a [drives] table gives: torque limits, friction, rotor inertia, encoders."""
    drives = doc.get("drives")
    if drives is None:
        return {}
    if not isinstance(drives, dict) or set(drives) - set(DRIVE_KEYS):
        raise RobotFileError(f"drives: keys are {', '.join(DRIVE_KEYS)}")
    missing = [k for k in DRIVE_KEYS[:-1] if k not in drives]
    if missing:
        raise RobotFileError(f"drives.{missing[0]}: missing")
    eta = vector(drives, "gear_ratio", 3, positive=True)
    motor = {k: number(drives, k, "drives.") for k in DRIVE_KEYS[1:-1]}
    if not motor["encoder_counts"].is_integer():
        raise RobotFileError(f"drives.encoder_counts: a whole number of counts a turn, got "
                             f"{drives['encoder_counts']!r}")
    rotors = drives.get("rotor_joints", joints)
    if not isinstance(rotors, list) or len(rotors) != 3 or not all(
            isinstance(r, str) and model.existJointName(r) for r in rotors):
        raise RobotFileError(f"drives.rotor_joints: must name 3 joints of the model, got "
                             f"{rotors!r}")
    return {"gear_ratio": eta, "torque_limits": eta * motor["peak_torque"],
            "friction": motor["torque_constant"] * motor["no_load_current"] * eta,
            "rotor": eta**2 * motor["rotor_inertia"], "rotor_joints": rotors,
            "encoder_resolution": 2 * np.pi / (motor["encoder_counts"] * eta)}


def _add_rotor(model: pin.Model, joint: str, inertia: float) -> None:
    """A rotor's reflected inertia about the axis of ``joint``: the armature of an actuated
    joint, else the body of that joint (one turning with the motor's output angle)."""
    jid = model.getJointId(joint)
    joint_model = model.joints[jid]
    if joint_model.nq == 1:
        model.armature[joint_model.idx_v] += inertia
        return
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    S = np.asarray(data.joints[jid].S).reshape(6, -1)[:, 0]
    axis = S[3:] / np.linalg.norm(S[3:])
    model.inertias[jid] = model.inertias[jid] + pin.Inertia(
        0.0, np.zeros(3), inertia * np.outer(axis, axis))


def _coupling(doc: dict) -> tuple:
    rows = doc.get("coupling", [])
    out = []
    for row in rows if isinstance(rows, list) else [None]:
        if not isinstance(row, dict) or set(row) != {"row", "lower", "upper"}:
            raise RobotFileError("coupling: a list of { row = [a, b, c], lower = .., upper = .. }")
        c = vector(row, "row", 3)
        lo, hi = (row[k] for k in ("lower", "upper"))
        if not all(is_number(v) and math.isfinite(v) for v in (lo, hi)) \
                or lo >= hi or not np.any(c):
            raise RobotFileError(f"coupling: lower < upper, both finite, and a row not zero, "
                                 f"got {row!r}")
        out.append((c, float(lo), float(hi)))
    return tuple(out)


def _drive_terms(doc: dict, model: pin.Model, drives: dict) -> np.ndarray:
    """The torque limits, armature, friction and damping into ``model``: the file's, else the
    drives', else the URDF's; the Coulomb friction below the torque limits. Returns the torque
    limits [N·m]."""
    urdf_effort = np.asarray(model.effortLimit, dtype=float).copy()
    if "torque_limits" not in doc and "torque_limits" not in drives and not np.all(
            urdf_effort > 0):
        raise RobotFileError(f"torque_limits: the URDF gives no effort limit > 0 "
                             f"({urdf_effort.tolist()}); give torque_limits [N·m]")
    torque = vector(doc, "torque_limits", 3, positive=True,
                    default=drives.get("torque_limits", urdf_effort))
    model.effortLimit[:] = torque
    model.armature[:] = vector(doc, "armature", 3, default=np.zeros(3))
    model.friction[:] = vector(doc, "friction", 3, default=drives.get("friction",
                                                                      model.friction))
    model.damping[:] = vector(doc, "damping", 3, default=model.damping)
    for key in ("armature", "friction", "damping"):
        if np.any(getattr(model, key) < 0):
            raise RobotFileError(f"{key}: must be ≥ 0")
    if np.any(model.friction >= torque):
        raise RobotFileError(f"friction: {listed(model.friction)} N·m, not below the torque "
                             f"limits {listed(torque)} N·m: the arm could not move")
    for joint, inertia in zip(drives.get("rotor_joints", ()), drives.get("rotor", ()),
                              strict=False):
        _add_rotor(model, joint, float(inertia))
    return torque


def _motor_map(doc: dict):
    """The file's ``motor_map`` (an invertible 3×3 matrix of numbers), or None."""
    motor_map = doc.get("motor_map")
    if motor_map is not None:
        S = floats(motor_map, (3, 3))
        if S is None or not np.all(np.isfinite(S)) or abs(np.linalg.det(S)) < 1e-9:
            raise RobotFileError(f"motor_map: must be an invertible 3x3 matrix, got {motor_map!r}")
    return motor_map


def _robot(doc: dict, path: Path) -> Robot:
    urdf = _urdf_path(doc, path.parent)
    model = _reduced(doc, _full_model(doc, urdf), urdf)
    _check_limits(model)
    joints = list(doc["joints"])
    ee_frame = _tool(doc, model)
    name = doc.get("name", re.sub(r"[^A-Za-z0-9_.-]", "_", path.stem))
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise RobotFileError(f"name: letters, digits, '_', '.' and '-', got {name!r}")
    drives = _drives(doc, model, joints)
    if "gravity" in doc:
        model.gravity.linear[:] = [0.0, 0.0, -number(doc, "gravity")]
    torque = _drive_terms(doc, model, drives)
    encoder = doc.get("encoder_resolution", drives.get("encoder_resolution"))
    motor_map = _motor_map(doc)
    try:
        description = str(doc.get("description", f"from {path.name} ({urdf.name})"))
        robot = Robot(
            name=name, model=model, ee_frame=ee_frame,
            q0=vector(doc, "home", 3), torque_limit=torque,
            encoder_resolution=None if encoder is None else vector(
                {"encoder_resolution": encoder}, "encoder_resolution", 3, positive=True),
            description=" ".join(description.split()), motor_map=motor_map,
            gear_ratio=drives.get("gear_ratio"), rotor_inertia=drives.get("rotor"),
            coupling=_coupling(doc))
    except RobotFileError:
        raise
    except ValueError as exc:  # the home posture outside the joint limits (Robot checks it)
        raise RobotFileError(f"home: {str(exc).split(': ', 1)[-1]}") from None
    check_home(robot, number(doc, "workspace") if "workspace" in doc else WORKSPACE)
    return robot


def robot_from_file(path: str | Path) -> Robot:
    """The robot a robot file describes.

    Raises
    ------
    RobotFileError
        For the first problem found, on one line: ``FILE: KEY: what is wrong``.
    """
    path = Path(path)
    try:
        return _robot(read_file(path), path)
    except RobotFileError as exc:
        raise RobotFileError(f"{path}: {' '.join(str(exc).split())}") from None
