"""ROS bags written for the tests with the ``rosbags`` library: every storage (rosbag2's MCAP and
SQLite 3, ROS 1) and every message type the reader takes, from positions and stamps the test
chooses."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

#: The epoch the tests' stamps start from [s]: a time of the 2020s, as a tracker stamps.
EPOCH = 1_700_000_000

#: The ROS 2 store's name of each type the tests write.
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
TRANSFORM_STAMPED = "geometry_msgs/msg/TransformStamped"
TF = "tf2_msgs/msg/TFMessage"
OLD_TF = "tf/msg/tfMessage"  # ROS 1 before tf2
POSE_ARRAY = "geometry_msgs/msg/PoseArray"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
STRING = "std_msgs/msg/String"


class Messages:
    """Builds the messages of one typestore (ROS 1 or ROS 2)."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        for tf in (TF, OLD_TF) if ros1 else ():  # ROS 1's store lacks them: their definition
            self.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                   tf))
        self.T = self.store.types

    def header(self, stamp_ns: int, frame: str = "tracker"):
        time = self.T["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9,
                                                     nanosec=stamp_ns % 10**9)
        extra = {"seq": 0} if self.ros1 else {}
        return self.T["std_msgs/msg/Header"](stamp=time, frame_id=frame, **extra)

    def point(self, p):
        return self.T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2]))

    def pose(self, p):
        q = self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        return self.T["geometry_msgs/msg/Pose"](position=self.point(p), orientation=q)

    def transform(self, stamp_ns: int, child: str, p):
        v = self.T["geometry_msgs/msg/Vector3"](x=float(p[0]), y=float(p[1]), z=float(p[2]))
        q = self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        tr = self.T["geometry_msgs/msg/Transform"](translation=v, rotation=q)
        return self.T[TRANSFORM_STAMPED](header=self.header(stamp_ns, "world"),
                                         child_frame_id=child, transform=tr)

    def marker(self, stamp_ns: int, ident: int, p, action: int = 0):
        T = self.T
        empty = np.zeros(0, np.uint8)
        extra = {} if self.ros1 else {  # ROS 2's textured and embedded meshes, left empty
            "texture_resource": "", "uv_coordinates": [],
            "texture": T["sensor_msgs/msg/CompressedImage"](header=self.header(0), format="",
                                                            data=empty),
            "mesh_file": T["visualization_msgs/msg/MeshFile"](filename="", data=empty)}
        return T["visualization_msgs/msg/Marker"](
            header=self.header(stamp_ns), ns="tracker", id=ident, type=2, action=action,
            pose=self.pose(p), scale=T["geometry_msgs/msg/Vector3"](x=1.0, y=1.0, z=1.0),
            color=T["std_msgs/msg/ColorRGBA"](r=1.0, g=0.0, b=0.0, a=1.0),
            lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
            points=[], colors=[], text="", mesh_resource="", mesh_use_embedded_materials=False,
            **extra)

    def make(self, msgtype: str, stamp_ns: int, positions: np.ndarray, frame: str = "tool"):
        """A message of ``msgtype`` at ``stamp_ns`` holding ``positions`` (P, 3) [m]."""
        T = self.T
        if msgtype == POSE_STAMPED:
            return T[msgtype](header=self.header(stamp_ns), pose=self.pose(positions[0]))
        if msgtype == POINT_STAMPED:
            return T[msgtype](header=self.header(stamp_ns), point=self.point(positions[0]))
        if msgtype == TRANSFORM_STAMPED:
            return self.transform(stamp_ns, frame, positions[0])
        if msgtype in (TF, OLD_TF):  # the POI's frame beside a second one, each its own
            return T[msgtype](transforms=[self.transform(stamp_ns, "camera", positions[0] + 1),
                                          self.transform(stamp_ns, frame, positions[0])])
        if msgtype == POSE_ARRAY:
            return T[msgtype](header=self.header(stamp_ns),
                              poses=[self.pose(p) for p in positions])
        if msgtype == MARKER_ARRAY:  # published in reverse id order, a deleted one among them
            markers = [self.marker(stamp_ns, k, p) for k, p in enumerate(positions)][::-1]
            markers.append(self.marker(stamp_ns, 99, positions[0] + 5, action=2))
            return T[msgtype](markers=markers)
        if msgtype == STRING:
            return T[msgtype](data="frame")
        raise ValueError(msgtype)

    def serialize(self, msg, msgtype: str) -> bytes:
        if self.ros1:
            return self.store.serialize_ros1(msg, msgtype)
        return self.store.serialize_cdr(msg, msgtype)


def write_bag(path: Path, storage: str, topics: dict[str, tuple[str, Sequence]]) -> Path:
    """Write a bag at ``path``: ``storage`` ``"mcap"`` or ``"sqlite3"`` (a rosbag2 folder) or
    ``"ros1"`` (a ``.bag`` file); ``topics``: name → (type, [(receive_ns, stamp_ns, positions
    (P, 3) [m]), …]) in any order (written in receive order). Returns ``path``."""
    ros1 = storage == "ros1"
    build = Messages(ros1)
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=8, storage_plugin=plugin)
    with writer:
        queue = []
        for name, (msgtype, messages) in topics.items():
            conn = writer.add_connection(name, msgtype, typestore=build.store)
            queue += [(receive, name, conn, msgtype, stamp, pos)
                      for receive, stamp, pos in messages]
        for receive, _, conn, msgtype, stamp, pos in sorted(queue, key=lambda q: (q[0], q[1])):
            msg = build.make(msgtype, stamp, np.atleast_2d(pos))
            writer.write(conn, receive, build.serialize(msg, msgtype))
    return path


def track(rng: np.random.Generator, n: int, rate: float = 25.0, points: int = 1,
          lag: tuple[float, float] = (0.003, 0.009)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` samples of ``points`` points moving as a heart surface does (1.5 Hz, 2–4 mm) at
    ``rate`` [Hz] from :data:`EPOCH`: (stamp_ns (n,), receive_ns (n,) lagging the stamps by a
    uniform draw in ``lag`` [s], positions (n, points, 3) [m])."""
    t = np.arange(n) / rate
    stamps = EPOCH * 10**9 + np.rint(t * 1e9).astype(np.int64)
    receive = stamps + np.rint(rng.uniform(*lag, n) * 1e9).astype(np.int64)
    amp = rng.uniform(2e-3, 4e-3, (points, 3))
    phase = rng.uniform(0, 2 * np.pi, (points, 3))
    z = amp * np.sin(2 * np.pi * 1.5 * t[:, None, None] + phase) + 0.05 * np.arange(points)[:, None]
    return stamps, receive, z


def messages(stamps, receive, z) -> list:
    """The (receive_ns, stamp_ns, positions) rows :func:`write_bag` takes."""
    return [(int(r), int(s), p) for r, s, p in zip(receive, stamps, z, strict=True)]
