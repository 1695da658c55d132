"""The static scene of the 3-D replay (:mod:`rhmpc.report.replay`) as meshcat commands: the
arm from its Pinocchio model (links as cylinders between the joint frames, joints as short
cylinders along their axes, a pedestal under the base), the paths of the point of interest (POI)
and of the tool, the measured samples, and the markers the player moves (the POI and the
forecast horizon).

Units: positions in metres (the workspace frame of the run).
"""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import umsgpack

with warnings.catch_warnings():  # meshcat's package imports its server's deprecated zmq loop
    warnings.simplefilter("ignore", DeprecationWarning)
    import meshcat.commands as mc
    import meshcat.geometry as mg
    from meshcat.path import Path as MeshcatPath

#: Colours of the page (RGB hex), matching the figures of :mod:`rhmpc.report.figures`.
COLOURS = {"poi": 0xD62728, "tool": 0x1F77B4, "forecast": 0x2CA02C, "samples": 0xFF7F0E,
           "link": 0xB8BCC2, "joint": 0x4A4F57}

def scene_commands(robot, scene: dict) -> list[bytes]:
    """The static scene as meshcat commands (msgpack), in the order the viewer runs them."""
    cmds = (_setting_commands(scene["extent"]) + _arm_commands(robot, scene)
            + _path_commands(scene) + _marker_commands(scene))
    return [umsgpack.packb(c.lower()) for c in cmds]


def _path(*parts: str):
    return MeshcatPath(tuple(p for part in parts for p in part.split("/") if p))


def _setting_commands(extent: tuple[np.ndarray, np.ndarray]) -> list:
    """A light background, and the viewer's floor grid (20 m by 0.5 m) scaled to 1 m by 25 mm
    just under the lowest drawn point."""
    grid = np.diag([0.05, 0.05, 0.05, 1.0])
    grid[2, 3] = float(extent[0][2]) - 0.02
    return [mc.SetProperty("top_color", [0.97, 0.97, 0.98], _path("Background")),
            mc.SetProperty("bottom_color", [0.78, 0.81, 0.86], _path("Background")),
            mc.SetTransform(grid, _path("Grid")),
            mc.SetProperty("visible", False, _path("Axes"))]


def _arm_commands(robot, scene: dict) -> list:
    """Each joint's group (``meshcat/replay/arm/<joint>``) with its parts at fixed local
    placements; the player moves the groups."""
    model = robot.model
    reach = _reach(robot)
    link = mg.MeshLambertMaterial(color=COLOURS["link"], transparent=True, opacity=0.55)
    joint = mg.MeshLambertMaterial(color=COLOURS["joint"])
    cmds = []
    for j, parts in arm_parts(robot).items():
        name = "base" if j == 0 else model.names[j]
        for k, (kind, a, b) in enumerate(parts):
            where = _path("meshcat/replay/arm", name, f"{kind}{k}")
            if kind == "link":
                geom, mat = mg.Cylinder(float(np.linalg.norm(b - a)), 0.012 * reach), link
                pose = _segment_pose(a, b)
            else:  # a joint: a short cylinder along its axis (b) at a
                geom, mat = mg.Cylinder(0.05 * reach, 0.025 * reach), joint
                pose = _segment_pose(a - 0.5 * b, a + 0.5 * b)
            cmds += [mc.SetObject(geom, mat, where), mc.SetTransform(pose, where)]
    tool = robot.model.frames[robot.ee_frame_id]
    where = _path("meshcat/replay/arm", model.names[tool.parentJoint], "tool")
    pose = np.eye(4)
    pose[:3, 3] = tool.placement.translation
    cmds += [mc.SetObject(mg.Sphere(scene["marker"]), mg.MeshLambertMaterial(
        color=COLOURS["tool"]), where), mc.SetTransform(pose, where)]
    base_pose = np.eye(4)
    base_pose[:3, 3] = scene["placements"][0, :3]
    floor = float(scene["extent"][0][2]) - 0.02
    height = max(base_pose[2, 3] - floor, 1e-3)
    cmds.append(mc.SetObject(mg.Cylinder(height, 0.06 * reach), joint,
                             _path("meshcat/replay/arm/base/pedestal")))
    cmds.append(mc.SetTransform(_segment_pose(np.array([*base_pose[:2, 3], floor]),
                                              base_pose[:3, 3]),
                                _path("meshcat/replay/arm/base/pedestal")))
    return cmds


def arm_parts(robot) -> dict[int, list[tuple[str, np.ndarray, np.ndarray]]]:
    """What draws each joint's body, in the joint's frame: ``("link", a, b)``, a bar from a to b
    (to each child joint and to each frame placed away from the joint; a body with neither, to
    twice its centre of mass), and ``("joint", origin, axis)``, the revolute joint itself."""
    model, data = robot.model, robot.create_data()
    pin.forwardKinematics(model, data, robot.q0)
    reach = _reach(robot)
    parts: dict[int, list] = {j: [] for j in range(1, model.njoints)}
    zero = np.zeros(3)
    for j in range(1, model.njoints):
        axis = np.asarray(data.joints[j].S).reshape(6, -1)[3:, 0]
        if np.linalg.norm(axis) > 0.5:
            parts[j].append(("joint", zero, axis / np.linalg.norm(axis)))
        children = [np.array(model.jointPlacements[c].translation)
                    for c in range(j + 1, model.njoints) if model.parents[c] == j]
        ends = [e for e in children + [np.array(f.placement.translation) for f in model.frames
                                       if f.parentJoint == j and f.type != pin.FrameType.JOINT]
                if np.linalg.norm(e) > 0.02 * reach]
        lever = np.array(model.inertias[j].lever)
        if not children and not ends and np.linalg.norm(lever) > 0.02 * reach:
            ends = [2.0 * lever]
        parts[j] += [("link", zero, e) for e in _unique(ends)]
    return parts


def _unique(points: list[np.ndarray]) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for p in points:
        if all(np.linalg.norm(p - o) > 1e-6 for o in out):
            out.append(p)
    return out


def _reach(robot) -> float:
    """The arm's size [m]: the farthest joint or frame origin from the base at home (≥ 0.1 m)."""
    model, data = robot.model, robot.create_data()
    pin.framesForwardKinematics(model, data, robot.q0)
    far = [np.linalg.norm(m.translation) for m in (*data.oMi, *data.oMf)]
    return max(float(max(far)), 0.1)


def _segment_pose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The placement of a three.js cylinder (axis y, centred) that spans from a to b."""
    d = b - a
    y = d / np.linalg.norm(d)
    helper = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([x, y, np.cross(x, y)])
    pose[:3, 3] = 0.5 * (a + b)
    return pose


def _path_commands(scene: dict) -> list:
    """The POI's and the tool's paths (faint, whole; the player draws the trail) and the
    measured samples (the player shows those of the trail's span)."""
    cmds = []
    for name in ("poi", "tool"):
        pts = scene[f"{name}_path"].T.astype(np.float32)
        faint = mg.LineBasicMaterial(color=COLOURS[name], transparent=True, opacity=0.3)
        bright = mg.LineBasicMaterial(color=COLOURS[name])
        cmds += [mc.SetObject(mg.Line(mg.PointsGeometry(pts), faint),
                              path=_path(f"meshcat/replay/{name} path/whole")),
                 mc.SetObject(mg.Line(mg.PointsGeometry(pts[:, :2]), bright),
                              path=_path(f"meshcat/replay/{name} path/trail"))]
    if scene["samples"].size:
        cmds.append(mc.SetObject(mg.Points(mg.PointsGeometry(
            scene["samples"].T.astype(np.float32)), _PixelPoints(COLOURS["samples"], 2.5)),
            path=_path("meshcat/replay/samples")))
    return cmds


def _marker_commands(scene: dict) -> list:
    """The POI (a sphere the player moves) and the forecast horizon (a line and its points)."""
    radius = scene["marker"]
    n = scene["horizon_points"]
    line = mg.PointsGeometry(np.zeros((3, n), np.float32))
    return [
        mc.SetObject(mg.Sphere(radius), mg.MeshLambertMaterial(color=COLOURS["poi"]),
                     _path("meshcat/replay/poi")),
        mc.SetObject(mg.Line(line, mg.LineBasicMaterial(color=COLOURS["forecast"])),
                     path=_path("meshcat/replay/forecast/line")),
        mc.SetObject(mg.Points(mg.PointsGeometry(np.zeros((3, n), np.float32)),
                               _PixelPoints(COLOURS["forecast"], 5.0)),
                     path=_path("meshcat/replay/forecast/points")),
    ]


class _PixelPoints(mg.Material):
    """Points of one colour and a fixed size on screen [px] (meshcat's own ``PointsMaterial``
    asks for a colour per vertex)."""

    def __init__(self, color: int, size: float) -> None:
        super().__init__()
        self.color, self.size = color, size

    def lower(self, object_data: dict) -> dict:
        return {"uuid": self.uuid, "type": "PointsMaterial", "color": self.color,
                "size": self.size, "sizeAttenuation": False}
