"""The ROS 2 messages the bridges read and publish, each defined once as ROS 2 defines it.

A ROS 2 node on Cyclone DDS (``rmw_cyclonedds_cpp``, Humble and Jazzy) registers each message
type with DDS under the name ``PKG::msg::dds_::NAME_`` and writes it as plain CDR
(XCDR version 1, little-endian): the fields in their order, each aligned to its size, a
string as its length with the terminating NUL then its bytes, a sequence as its length then
its elements. The structures below are those of the ``.msg`` files of
``builtin_interfaces``, ``std_msgs``, ``geometry_msgs``, ``nav_msgs``, ``sensor_msgs`` and
``diagnostic_msgs`` (the same in Humble and Jazzy), field for field, as final (non-extensible)
types of ``cyclonedds``' IDL, so that a sample's bytes are those a ROS 2 node writes and
reads. The tests compare them with an independent serializer (``rosbags``' type stores for
Humble and Jazzy).

This module imports ``cyclonedds`` (the ``ros2`` extra): only the bridges import it.
"""

from dataclasses import dataclass, field

import numpy as np
from cyclonedds.idl import Endianness, IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import byte, float64, int32, sequence, uint32

from rhmpc.runtime.ros2.cdr import CDR_LE, CdrError, codec

__all__ = ["MESSAGES", "DiagnosticStatus", "Header", "JointState", "KeyValue", "Path", "Point",
           "Pose", "PoseArray", "PoseStamped", "Quaternion", "Time", "message_name",
           "nanoseconds", "point_of", "pose_at", "time_of"]


def _dds(name: str) -> str:
    """The DDS type name of ROS 2's ``PKG/msg/NAME``: ``PKG::msg::dds_::NAME_``."""
    package, _, message = name.split("/")
    return f"{package}::msg::dds_::{message}_"


def _plain_cdr(cls: type) -> type:
    """``cls`` serialized and deserialized by its plain-CDR codec
    (:mod:`rhmpc.runtime.ros2.cdr`), the encoding ROS 2 writes; any other encoding
    ``cyclonedds`` asks for goes to its own serializer."""
    generic_serialize, generic_deserialize = cls.serialize, cls.deserialize

    def serialize(self, buffer=None, endianness=None, use_version_2=None) -> bytes:
        if use_version_2 or buffer is not None or endianness not in (None, Endianness.Little):
            return generic_serialize(self, buffer, endianness, use_version_2)
        return codec(cls).encode(self)

    def deserialize(klass, data, has_header: bool = True, use_version_2=None):
        if has_header and bytes(data[:2]) == CDR_LE[:2]:
            return codec(cls).decode(data)
        try:  # another encoding (big-endian, XCDR2): cyclonedds' own, its errors made one
            return generic_deserialize(data, has_header, use_version_2)
        except Exception as exc:
            raise CdrError(f"{type(exc).__name__}: {exc}") from None

    cls.serialize, cls.deserialize = serialize, classmethod(deserialize)
    return cls


@_plain_cdr
@final
@dataclass
class Time(IdlStruct, typename=_dds("builtin_interfaces/msg/Time")):
    """``builtin_interfaces/Time``: an instant, ``sec + nanosec · 1e-9`` [s]."""

    sec: int32 = 0
    nanosec: uint32 = 0


@_plain_cdr
@final
@dataclass
class Header(IdlStruct, typename=_dds("std_msgs/msg/Header")):
    """``std_msgs/Header``: the instant the data are of and their frame."""

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@_plain_cdr
@final
@dataclass
class Point(IdlStruct, typename=_dds("geometry_msgs/msg/Point")):
    """``geometry_msgs/Point`` [m]."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@_plain_cdr
@final
@dataclass
class Quaternion(IdlStruct, typename=_dds("geometry_msgs/msg/Quaternion")):
    """``geometry_msgs/Quaternion`` (ROS 2's default: the identity, w = 1)."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@_plain_cdr
@final
@dataclass
class Pose(IdlStruct, typename=_dds("geometry_msgs/msg/Pose")):
    """``geometry_msgs/Pose``: a position [m] and an orientation."""

    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@_plain_cdr
@final
@dataclass
class PoseStamped(IdlStruct, typename=_dds("geometry_msgs/msg/PoseStamped")):
    """``geometry_msgs/PoseStamped``: a pose at an instant, in a frame."""

    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@_plain_cdr
@final
@dataclass
class PoseArray(IdlStruct, typename=_dds("geometry_msgs/msg/PoseArray")):
    """``geometry_msgs/PoseArray``: poses of one instant, in one frame."""

    header: Header = field(default_factory=Header)
    poses: sequence[Pose] = field(default_factory=list)


@_plain_cdr
@final
@dataclass
class Path(IdlStruct, typename=_dds("nav_msgs/msg/Path")):
    """``nav_msgs/Path``: poses each at its own instant."""

    header: Header = field(default_factory=Header)
    poses: sequence[PoseStamped] = field(default_factory=list)


@_plain_cdr
@final
@dataclass
class JointState(IdlStruct, typename=_dds("sensor_msgs/msg/JointState")):
    """``sensor_msgs/JointState``: joints by name, their positions [rad], velocities [rad/s]
    and efforts [N·m] (each list empty or one value per name)."""

    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@_plain_cdr
@final
@dataclass
class KeyValue(IdlStruct, typename=_dds("diagnostic_msgs/msg/KeyValue")):
    """``diagnostic_msgs/KeyValue``: one named value, as text."""

    key: str = ""
    value: str = ""


@_plain_cdr
@final
@dataclass
class DiagnosticStatus(IdlStruct, typename=_dds("diagnostic_msgs/msg/DiagnosticStatus")):
    """``diagnostic_msgs/DiagnosticStatus``: a level (:data:`OK`, :data:`WARN`,
    :data:`ERROR`, :data:`STALE`), a name, a message, and named values."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3

    level: byte = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


#: Every message type, by its ROS 2 name.
MESSAGES = {f"{t.__idl_typename__.split('::')[0]}/msg/{t.__name__}": t
            for t in (Time, Header, Point, Quaternion, Pose, PoseStamped, PoseArray, Path,
                      JointState, KeyValue, DiagnosticStatus)}


def message_name(message_type: type) -> str:
    """The ROS 2 name of one of :data:`MESSAGES` (``geometry_msgs/msg/PoseStamped``)."""
    return next(name for name, t in MESSAGES.items() if t is message_type)


def point_of(pose: Pose) -> np.ndarray:
    """The position of ``pose`` (3,) [m]."""
    p = pose.position
    return np.array([p.x, p.y, p.z], dtype=float)


def pose_at(point) -> Pose:
    """A pose at ``point`` (3,) [m] with the identity orientation."""
    x, y, z = (float(v) for v in point)
    return Pose(Point(x, y, z))


def time_of(ns: int) -> Time:
    """``Time`` of an instant [ns]: whole seconds and ``nanosec`` in [0, 1e9)."""
    return Time(*divmod(int(ns), 1_000_000_000))


def nanoseconds(stamp: Time) -> int:
    """The instant of ``stamp`` [ns]."""
    return stamp.sec * 1_000_000_000 + stamp.nanosec
