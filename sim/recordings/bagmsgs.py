"""The ROS messages a recording is read from, and the positions and stamps each one gives.

Positions are in metres, as ROS states them (REP 103); each sample's time is its message's
header stamp.

``geometry_msgs/PoseStamped``
    ``pose.position``.
``geometry_msgs/PointStamped``
    ``point``.
``geometry_msgs/TransformStamped``
    ``transform.translation``; ``--frame`` names the child frame it must have.
``tf2_msgs/TFMessage`` (and ROS 1's older ``tf/tfMessage``)
    The translation of each transform to the child frame ``--frame``, at its own stamp.
``geometry_msgs/PoseArray``
    ``poses[k].position`` is point k + 1 (``--poi``).
``visualization_msgs/MarkerArray``
    The markers shown (action ADD), ordered by their namespace and id: the k-th is point k + 1
    (``--poi``), so that a tracker that publishes them in another order each time keeps each
    point's trajectory; the stamp is the first marker's.

A frame name is compared without a leading ``/`` (ROS 1's tf wrote ``/tool``, tf2 writes
``tool``). A message gives samples ``(frame, stamp, positions)``: the child frame for the
transforms (None otherwise), the stamp in nanoseconds since the epoch and the positions of its
points, (P, 3) [m].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

__all__ = ["MARKER_ADD", "TYPES", "MessageType", "Sample", "frame_name", "read_types",
           "stamp_ns", "type_name"]

class Sample(NamedTuple):
    """One sample of a message.

    Attributes
    ----------
    frame : str or None
        The child frame of a transform; None for a message of one frame.
    stamp : int
        The header's stamp [ns].
    points : list of (float, float, float)
        The positions [m], one per tracked point.
    """

    frame: str | None
    stamp: int
    points: list[tuple[float, float, float]]


@dataclass(frozen=True)
class MessageType:
    """A message type a recording is read from.

    Attributes
    ----------
    name : str
        Its name as ROS writes it in a command (``geometry_msgs/PoseStamped``).
    samples : callable
        ``samples(msg) -> list[Sample]``: what a message of this type gives.
    points : bool
        Whether it holds several tracked points (``--poi N`` picks one).
    frames : bool
        Whether its samples are transforms to child frames (``--frame`` picks one).
    """

    name: str
    samples: Callable[[object], list[Sample]]
    points: bool = False
    frames: bool = False


def stamp_ns(stamp) -> int:
    """A ``builtin_interfaces/Time`` (ROS 1's ``time``) in nanoseconds: sec·10⁹ + nanosec."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def frame_name(frame: str) -> str:
    """A tf frame's name without a leading ``/``."""
    return str(frame).lstrip("/")


def _xyz(v) -> tuple[float, float, float]:
    return float(v.x), float(v.y), float(v.z)


def _pose_stamped(msg) -> list[Sample]:
    return [Sample(None, stamp_ns(msg.header.stamp), [_xyz(msg.pose.position)])]


def _point_stamped(msg) -> list[Sample]:
    return [Sample(None, stamp_ns(msg.header.stamp), [_xyz(msg.point)])]


def _transform_stamped(msg) -> list[Sample]:
    return [Sample(frame_name(msg.child_frame_id), stamp_ns(msg.header.stamp),
                   [_xyz(msg.transform.translation)])]


def _tf_message(msg) -> list[Sample]:
    return [sample for transform in msg.transforms for sample in _transform_stamped(transform)]


def _pose_array(msg) -> list[Sample]:
    if not msg.poses:
        return []
    return [Sample(None, stamp_ns(msg.header.stamp), [_xyz(p.position) for p in msg.poses])]


#: ``visualization_msgs/Marker``'s action ADD (also MODIFY): a marker that is shown.
MARKER_ADD = 0


def _marker_array(msg) -> list[Sample]:
    shown = sorted((m for m in msg.markers if m.action == MARKER_ADD), key=lambda m: (m.ns, m.id))
    if not shown:
        return []
    return [Sample(None, stamp_ns(shown[0].header.stamp),
                   [_xyz(m.pose.position) for m in shown])]


#: The message types read, by the name a bag's connection gives (``pkg/msg/Name``).
TYPES: dict[str, MessageType] = {
    "geometry_msgs/msg/PoseStamped": MessageType("geometry_msgs/PoseStamped", _pose_stamped),
    "geometry_msgs/msg/PointStamped": MessageType("geometry_msgs/PointStamped", _point_stamped),
    "geometry_msgs/msg/TransformStamped": MessageType("geometry_msgs/TransformStamped",
                                                      _transform_stamped, frames=True),
    "tf2_msgs/msg/TFMessage": MessageType("tf2_msgs/TFMessage", _tf_message, frames=True),
    "tf/msg/tfMessage": MessageType("tf/tfMessage", _tf_message, frames=True),  # ROS 1 before tf2
    "geometry_msgs/msg/PoseArray": MessageType("geometry_msgs/PoseArray", _pose_array,
                                               points=True),
    "visualization_msgs/msg/MarkerArray": MessageType("visualization_msgs/MarkerArray",
                                                      _marker_array, points=True),
}


def type_name(msgtype: str | None) -> str:
    """A connection's type as ROS writes it in a command: ``pkg/Name``."""
    return "several types" if msgtype is None else msgtype.replace("/msg/", "/")


def read_types() -> str:
    """The types read, for a message."""
    return ", ".join(t.name for t in TYPES.values())
