"""A closed-loop run replayed in 3-D: one HTML page that opens offline in any browser.

:func:`write_replay` draws the arm from its Pinocchio model, the point of interest (POI), the
tool, the measured samples and the forecast horizon of each refresh (the scene:
:mod:`rhmpc.report.replay_scene`), and animates them at a fixed frame
rate of simulated time. The page inlines meshcat's three.js viewer (the ``meshcat`` package's
``main.min.js``), the scene as meshcat commands and the animation as base64 arrays, so it loads
nothing from the network. Its controls: play and pause (also the space bar), a time slider, the
playback speed, three views and a help panel (``?``).

Views
    ``follow`` (the first): the camera rides with the POI at :data:`FOLLOW_SPAN` times the
    median 25-ms travel of the forecasts, so that a forecast spans about a third of the view
    and its shape reads, with the last second of the paths; ``path``: the POI's whole path;
    ``arm``: the whole arm. The follow and path views look at the POI from the side of its
    path's plane away from the forearm (the bar that carries the tool), so that the arm is
    behind what they show; the markers keep their size on the screen.
The address
    ``page.html#t=2.5`` starts at 2.5 s of the run (default: within the second after the
    settling span, where the forecasts have converged, the frame whose forecast travels
    farthest), ``&paused`` starts paused, ``&path`` or ``&arm`` starts in that view; e.g.
    ``run.html#t=12&paused&arm``.

Units: positions in metres (the workspace frame of the run), time in seconds.
"""

from __future__ import annotations

import base64
import html
import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from rhmpc import io
from rhmpc.report.replay_scene import COLOURS, scene_commands

with warnings.catch_warnings():  # meshcat's package imports its server's deprecated zmq loop
    warnings.simplefilter("ignore", DeprecationWarning)
    import meshcat

#: Path points drawn per animation frame (the POI's and the tool's paths).
PATH_POINTS_PER_FRAME = 4
#: Simulated seconds of the bright trail behind the POI and the tool.
TRAIL_S = 1.0
#: At most this many points of each forecast horizon are drawn (evenly spaced, both ends kept).
HORIZON_POINTS = 25
#: The follow view's camera distance, in median forecast travels (a view about three times as
#: tall as that travel: the fov of meshcat's camera is 75°).
FOLLOW_SPAN = 2.0
#: The follow view's camera distance is kept within these bounds [m].
FOLLOW_RANGE = (2e-3, 3e-2)


@dataclass(frozen=True)
class ReplayInfo:
    """What :func:`write_replay` wrote.

    Attributes
    ----------
    path : pathlib.Path
        The HTML file.
    frames : int
        Animation frames.
    start, stop : float
        The replayed span of the run [s].
    fps : float
        Frames per simulated second.
    size : int
        File size [bytes].
    """

    path: Path
    frames: int
    start: float
    stop: float
    fps: float
    size: int


def write_replay(path: str | Path, result, robot, *, fps: float = 60.0, max_frames: int = 3600,
                 window: tuple[float, float] | None = None, title: str = "") -> ReplayInfo:
    """Write a run's 3-D replay as one self-contained HTML file.

    Parameters
    ----------
    path : str or pathlib.Path
        The page to write.
    result : rhmpc.sim.loop.LoopResult
        The run: its trace (``time``, ``ee``, ``poi`` and ``trace["q"]``, the joint angles),
        ``settings.Ts``, and where present ``horizons`` = (ticks (R,), points (R, N, 3)), the
        reference points of each refresh, and ``samples`` = (t (S,), z (S, 3)), the measured
        samples placed in the workspace [m].
    robot : rhmpc.robots.Robot
        The arm the run drove (its Pinocchio model draws and poses it).
    fps : float
        Animation frames per simulated second.
    max_frames : int
        At most this many frames: a longer run is replayed over its last ``max_frames / fps``
        seconds (the trace keeps those at full rate).
    window : tuple of float, optional
        The span to replay [s]; default: the whole run, or its end as above.
    title : str
        The page's heading.

    Returns
    -------
    ReplayInfo
        The file, its frame count, span and size.
    """
    if "q" not in result.trace:
        raise ValueError("the run's trace holds no joint angles (trace['q']): nothing to pose "
                         "the arm with")
    t_frames = frame_times(np.asarray(result.time, float), fps, max_frames, window)
    data = _animation(result, robot, t_frames, fps)
    data["title"] = title or "rhmpc replay"
    commands = scene_commands(robot, data.pop("_scene"))
    page = _page(commands, data)
    path = io.write_text(path, page)
    return ReplayInfo(path, t_frames.size, float(t_frames[0]), float(t_frames[-1]), float(fps),
                      path.stat().st_size)


def frame_times(time: np.ndarray, fps: float, max_frames: int,
                window: tuple[float, float] | None = None) -> np.ndarray:
    """The instants of the animation frames [s]: ``fps`` a simulated second over ``window``
    (clipped to the trace), or over the whole trace, or over its last ``max_frames`` frames."""
    if fps <= 0 or max_frames < 2:
        raise ValueError("fps must be positive and max_frames at least 2")
    lo, hi = float(time[0]), float(time[-1])
    if window is not None:
        lo, hi = max(lo, float(window[0])), min(hi, float(window[1]))
        if hi <= lo:
            raise ValueError(f"window {window} does not overlap the run [{time[0]}, {time[-1]}] s")
    n = int(np.floor((hi - lo) * fps + 1e-9)) + 1
    if n > max_frames:
        lo, n = hi - (max_frames - 1) / fps, max_frames
    return lo + np.arange(n) / fps


def _interp(t: np.ndarray, time: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` (n, d) sampled at ``time`` (n,), linearly interpolated at ``t``."""
    return np.stack([np.interp(t, time, values[:, k]) for k in range(values.shape[1])], axis=1)


def _animation(result, robot, t_frames: np.ndarray, fps: float) -> dict:
    """The page's arrays (base64) and numbers, and the scene's static part under ``_scene``."""
    time = np.asarray(result.time, float)
    q = _interp(t_frames, time, np.asarray(result.trace["q"], float))
    poses, placements = joint_poses(robot, q)
    t_path = t_frames[0] + np.arange((t_frames.size - 1) * PATH_POINTS_PER_FRAME + 1) / (
        fps * PATH_POINTS_PER_FRAME)
    poi_path = _interp(t_path, time, np.asarray(result.poi, float))
    index, horizons = forecast_frames(result, t_frames)
    samples, sample_counts = _samples(result, t_frames)
    tool_path = _interp(t_path, time, np.asarray(result.ee, float))
    scene = {"poi_path": poi_path, "tool_path": tool_path, "samples": samples,
             "horizon_points": horizons.shape[1] if horizons.size else 2,
             "placements": placements, "extent": _extent(
                 np.vstack([poi_path, tool_path, samples]), placements),
             "marker": float(np.clip(0.03 * _span(poi_path), 3e-4, 1.5e-3))}  # radius [m]
    centre = np.nan_to_num(np.nanmean(poi_path, axis=0), nan=0.0)
    settling = float(getattr(result.settings, "settling_s", t_frames[0]))
    return {
        "frames": int(t_frames.size), "fps": float(fps), "t0": float(t_frames[0]),
        "path_per_frame": PATH_POINTS_PER_FRAME, "trail": round(TRAIL_S * fps),
        "joints": [robot.model.names[j] for j in range(1, robot.model.njoints)],
        "poses": _b64(poses), "poi": _b64(_interp(t_frames, time, np.asarray(result.poi, float))),
        "horizon_index": _b64(index, np.int32), "horizons": _b64(horizons),
        "horizon_n": int(horizons.shape[1]) if horizons.size else 0,
        "sample_counts": _b64(sample_counts, np.int32), "has_samples": bool(samples.size),
        "centre": centre.tolist(), "arm_centre": (0.5 * (placements[0, :3] + centre)).tolist(),
        "poi_span": _span(poi_path),
        "near_dir": view_direction(poi_path, tool_path[0], _forearm_root(robot,
                                                                          placements)).tolist(),
        "arm_span": _span(np.vstack([placements[:, :3], centre[None]])), "_scene": scene,
        "start": start_time(t_frames, index, horizons, settling),
        "follow": follow_distance(horizons), "marker": scene["marker"],
        "tool_joint": robot.model.names[robot.model.frames[robot.ee_frame_id].parentJoint],
    }


def _span(points: np.ndarray) -> float:
    """The largest extent of finite points along an axis [m] (0 without any)."""
    finite = points[np.isfinite(points).all(axis=1)]
    return float(np.ptp(finite, axis=0).max()) if finite.size else 0.0


def _b64(array: np.ndarray, dtype=np.float32) -> str:
    """An array as base64 of its little-endian values (float32 unless told)."""
    return base64.b64encode(np.ascontiguousarray(array, dtype=np.dtype(dtype).newbyteorder("<"))
                            .tobytes()).decode("ascii")


def joint_poses(robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each joint frame's world placement per posture, by Pinocchio's forward kinematics.

    Returns
    -------
    poses : numpy.ndarray
        (F, J, 7): position [m] and unit quaternion (x, y, z, w) of joints 1…J per row of ``q``.
    home : numpy.ndarray
        (J, 7): the same at the first posture.
    """
    model, data = robot.model, robot.create_data()
    poses = np.empty((q.shape[0], model.njoints - 1, 7))
    for f, qf in enumerate(q):
        pin.forwardKinematics(model, data, qf)
        for j in range(1, model.njoints):
            poses[f, j - 1] = pin.SE3ToXYZQUAT(data.oMi[j])
    return poses, poses[0].copy()


def forecast_frames(result, t_frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The newest refresh at each frame: its index into the returned horizons (−1: none yet,
    or a forecast with a non-finite point), and the (U, n, 3) horizons the frames show [m]
    (n ≤ :data:`HORIZON_POINTS` of the N points, evenly spaced from the first to the last)."""
    horizons = getattr(result, "horizons", None)
    if horizons is None or len(horizons[0]) == 0:
        return np.full(t_frames.size, -1), np.zeros((0, 0, 3))
    ticks, points = np.asarray(horizons[0]), np.asarray(horizons[1], float)
    newest = np.searchsorted(ticks * result.settings.Ts, t_frames + 1e-12, side="right") - 1
    finite = np.isfinite(points).all(axis=(1, 2))
    newest = np.where((newest >= 0) & finite[np.maximum(newest, 0)], newest, -1)
    used, index = np.unique(newest, return_inverse=True)
    kept = used[used >= 0]
    index = np.where(newest >= 0, index - (used[0] < 0), -1)
    n = points.shape[1]
    leads = np.unique(np.linspace(0, n - 1, min(n, HORIZON_POINTS)).round().astype(int))
    return index, points[kept][:, leads]


def _samples(result, t_frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The finite measured samples within the replayed span (S, 3) [m], and how many of them
    had arrived at each frame."""
    samples = getattr(result, "samples", None)
    if samples is None or len(samples[0]) == 0:
        return np.zeros((0, 3)), np.zeros(t_frames.size, dtype=np.int32)
    t, z = np.asarray(samples[0], float), np.asarray(samples[1], float)
    keep = (t >= t_frames[0]) & (t <= t_frames[-1]) & np.isfinite(z).all(axis=1)
    t, z = t[keep], z[keep]
    order = np.argsort(t, kind="stable")
    return z[order], np.searchsorted(t[order], t_frames + 1e-12, side="right").astype(np.int32)


def _extent(points: np.ndarray, placements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners of everything drawn [m]."""
    allp = np.vstack([points[np.isfinite(points).all(axis=1)], placements[:, :3]])
    return allp.min(axis=0), allp.max(axis=0)


def _forearm_root(robot, placements: np.ndarray) -> np.ndarray:
    """Where the bar that carries the tool starts: its joint's position at the first frame [m]."""
    joint = robot.model.frames[robot.ee_frame_id].parentJoint
    return placements[joint - 1, :3]


def view_direction(path: np.ndarray, tool: np.ndarray, root: np.ndarray) -> np.ndarray:
    """A unit direction from the POI to the camera: onto the plane the path spans most (its
    least-variance axis), on the side away from the forearm (from ``tool`` to its ``root``),
    tilted a further half-unit away from it, so that the arm is behind the POI.

    Parameters
    ----------
    path : numpy.ndarray
        (n, 3) the POI's path [m].
    tool : numpy.ndarray
        (3,) the tool's position [m].
    root : numpy.ndarray
        (3,) where the bar that carries the tool starts [m].
    """
    arm = np.asarray(root, float) - np.asarray(tool, float)
    arm = arm / np.linalg.norm(arm) if np.linalg.norm(arm) > 0 else np.array([0.0, 0.0, 1.0])
    finite = path[np.isfinite(path).all(axis=1)]
    normal = (np.linalg.svd(finite - finite.mean(axis=0), full_matrices=False)[2][-1]
              if finite.shape[0] >= 3 else np.array([0.0, -1.0, 0.0]))
    normal = -normal if normal @ arm > 0 else normal
    d = normal - 0.5 * arm
    return d / np.linalg.norm(d)


def start_time(t_frames: np.ndarray, index: np.ndarray, horizons: np.ndarray,
               settling: float) -> float:
    """The first frame's time [s]: within the second after ``settling`` (clipped to the
    frames), the frame whose drawn forecast travels farthest (first to last point); the
    settling's end without forecasts."""
    lo = float(np.clip(settling, t_frames[0], t_frames[-1]))
    window = np.flatnonzero((t_frames >= lo - 1e-9) & (t_frames <= lo + 1.0) & (index >= 0))
    if window.size == 0 or horizons.size == 0:
        return lo
    travel = np.linalg.norm(horizons[index[window], -1] - horizons[index[window], 0], axis=1)
    return float(t_frames[window[int(np.nanargmax(travel))]])


def follow_distance(horizons: np.ndarray) -> float:
    """The follow view's camera distance [m]: :data:`FOLLOW_SPAN` median travels of the drawn
    forecasts (first to last point), within :data:`FOLLOW_RANGE`."""
    if horizons.size == 0:
        return FOLLOW_RANGE[1]
    travel = np.linalg.norm(horizons[:, -1] - horizons[:, 0], axis=1)
    travel = travel[np.isfinite(travel)]
    median = float(np.median(travel)) if travel.size else FOLLOW_RANGE[1]
    return float(np.clip(FOLLOW_SPAN * median, *FOLLOW_RANGE))


# -- the page ----------------------------------------------------------------------------------

def _viewer_js() -> str:
    """meshcat's bundled viewer (three.js, its controls and the scene tree), minified."""
    return (Path(meshcat.viewer_assets_path()) / "dist" / "main.min.js").read_text(
        encoding="utf-8")


def _page(commands: list[bytes], data: dict) -> str:
    """The HTML: the viewer, the commands and the arrays as JSON, and the player."""
    data = dict(data, commands=[base64.b64encode(c).decode("ascii") for c in commands])
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    viewer = _viewer_js()
    if "</script" in viewer.lower():
        raise RuntimeError("meshcat's viewer script cannot be inlined (it holds '</script')")
    return (_template("replay.html").replace("@TITLE@", html.escape(data["title"]))
            .replace("@LEGEND@", _legend())
            .replace("@VIEWER@", viewer)
            .replace("@DATA@", payload)
            .replace("@PLAYER@", _template("replay.js")))


def _template(name: str) -> str:
    """A file of the page (``rhmpc/report/templates``): its HTML, and the player's script
    (play, pause, the time slider, the animation of the arm, the paths and the forecasts)."""
    return (Path(__file__).with_name("templates") / name).read_text(encoding="utf-8")


def _legend() -> str:
    items = (("poi", "POI (truth)"), ("tool", "tool"), ("forecast", "forecast horizon"),
             ("samples", "measured samples"))
    return "".join(f'<span><i style="background:#{COLOURS[k]:06x}"></i>{label}</span>'
                   for k, label in items)
