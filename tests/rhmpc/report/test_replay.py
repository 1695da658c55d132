"""The 3-D replay (rhmpc.report.replay): a self-contained page whose arm follows Pinocchio,
drawn and animated in headless Chromium."""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import re
import select
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.report.replay import (
    forecast_frames,
    frame_times,
    joint_poses,
    write_replay,
)
from rhmpc.report.replay_scene import arm_parts
from tests.rhmpc.report.stand_in_run import stand_in_run

try:
    import fcntl  # the DevTools pipe: POSIX file descriptors
except ImportError:  # pragma: no cover
    fcntl = None

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--enable-logging=stderr", "--window-size=900,650",
         # WebGL on the CPU (SwiftShader): Chromium falls back to it without a GPU but warns
         # that the fallback is going away unless asked for
         "--enable-unsafe-swiftshader")


def chromium() -> str | None:
    """The Chromium on PATH when a test runs (not when the tests are collected: one installed
    in between is found)."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def page(phantom, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("replay") / "run.html"
    info = write_replay(path, stand_in_run(phantom, seconds=4.0), phantom, title="stand-in")
    assert info.frames == 240 and info.size == path.stat().st_size
    return path


def test_the_page_loads_nothing_from_outside(page: Path) -> None:
    text = page.read_text(encoding="utf-8")
    assert re.findall(r"<script[^>]*\bsrc\s*=", text, flags=re.I) == []
    assert re.findall(r"""(?:src|href)\s*=\s*["']?(?:https?:)?//""", text, flags=re.I) == []
    assert re.findall(r"""(?:import|fetch)\s*\(\s*["']https?:""", text) == []
    assert "MeshCat.Viewer" in text and "replay-data" in text


def test_a_twenty_second_run_stays_small(phantom, tmp_path) -> None:
    run = stand_in_run(phantom, seconds=20.0, stride=2)
    info = write_replay(tmp_path / "long.html", run, phantom)
    assert info.frames == 1200 and info.size < 2.5e6


def test_frames_cover_the_run_or_its_end() -> None:
    time = np.arange(1, 40_001) * 0.5e-3  # 20 s
    assert frame_times(time, 60.0, 3600).size == 1200
    end = frame_times(time, 60.0, 600)  # at most 10 s: the last 10 s
    assert end.size == 600 and end[-1] == pytest.approx(20.0, abs=1e-9)
    part = frame_times(time, 30.0, 3600, window=(5.0, 7.0))
    assert part[0] == 5.0 and part.size == 61
    with pytest.raises(ValueError, match="does not overlap"):
        frame_times(time, 60.0, 3600, window=(30.0, 40.0))


def test_each_frame_shows_the_newest_finite_forecast(phantom) -> None:
    run = stand_in_run(phantom, seconds=1.0, refresh_every=8)
    ticks, points = run.horizons
    points[3, 10] = np.nan  # a forecast with a non-finite point is not drawn
    t = np.array([0.0, 3 * 8 * 0.5e-3, 2 * 8 * 0.5e-3 + 1e-4, 0.5])
    index, shown = forecast_frames(run, t)
    assert index[1] == -1  # the refresh at tick 24 has a NaN
    np.testing.assert_allclose(shown[index[2]][0], points[2, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(shown[index[3]][-1], points[ticks == 1000][0, -1])
    assert index[0] == 0 and shown.shape[1] == 25  # 25 of the 50 points, both ends kept


def test_the_arm_is_drawn_from_its_model(phantom) -> None:
    """PHANToM: upper arm l1, crank l3, forearm l2 to the tip, the rear link to twice its
    centre of mass (= l1, the parallelogram), and a revolute joint at each joint frame."""
    parts = arm_parts(phantom)
    names = {phantom.model.names[j]: p for j, p in parts.items()}
    lengths = {n: sorted(round(float(np.linalg.norm(b - a)), 6) for kind, a, b in p
                         if kind == "link") for n, p in names.items()}
    assert lengths == {"yaw": [], "shoulder": [0.20955], "elbow": [0.169545],
                       "elbow_drive": [0.03175], "rear_link_pivot": [0.209555]}
    assert all(sum(kind == "joint" for kind, _, _ in p) == 1 for p in parts.values())


def test_the_tool_sits_where_pinocchio_puts_the_end_effector(phantom) -> None:
    q = phantom.q0 + np.array([[0.0, 0.0, 0.0], [0.2, -0.3, 0.4]])
    poses, _ = joint_poses(phantom, q)
    frame = phantom.model.frames[phantom.ee_frame_id]
    for f in range(2):
        joint = pin.XYZQUATToSE3(poses[f, frame.parentJoint - 1])
        np.testing.assert_allclose((joint * frame.placement).translation,
                                   phantom.ee_position(q[f]), atol=1e-12)


def test_a_trace_without_joint_angles_is_refused(phantom, tmp_path) -> None:
    run = stand_in_run(phantom, seconds=0.5)
    del run.trace["q"]
    with pytest.raises(ValueError, match="joint angles"):
        write_replay(tmp_path / "x.html", run, phantom)


# -- in the browser ------------------------------------------------------------------------------

class DevTools:
    """Chromium driven through its DevTools protocol on a pipe (it reads commands on fd 3 and
    writes replies on fd 4, each a JSON message ended by a NUL byte)."""

    def __init__(self, binary: str, url: str, workdir: Path) -> None:
        commands, self._write = os.pipe()
        self._read, replies = os.pipe()
        # out of the way of fds 3 and 4, which the child sets up
        commands, replies = (fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10) for fd in (commands,
                                                                                     replies))

        def child_fds() -> None:
            os.dup2(commands, 3)
            os.dup2(replies, 4)

        (workdir / "profile").mkdir()
        self.log = workdir / "chromium.log"
        with open(self.log, "w") as log:
            self.proc = subprocess.Popen(
                [binary, *FLAGS, f"--user-data-dir={workdir / 'profile'}",
                 "--remote-debugging-pipe", url],
                stdin=subprocess.DEVNULL, stdout=log, stderr=log, close_fds=False,
                preexec_fn=child_fds)
        for fd in (commands, replies):
            os.close(fd)
        self._buffer, self._id = b"", 0
        page = next(t for t in self.call("Target.getTargets")["targetInfos"]
                    if t["type"] == "page")
        self.target_session = self.call("Target.attachToTarget", targetId=page["targetId"],
                                        flatten=True)["sessionId"]

    def call(self, method: str, target_session: str | None = None, **params) -> dict:
        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if target_session:
            message["sessionId"] = target_session
        os.write(self._write, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._next()
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def _next(self) -> dict:
        while b"\0" not in self._buffer:
            if not select.select([self._read], [], [], 60)[0]:
                raise TimeoutError("chromium did not answer within 60 s")
            chunk = os.read(self._read, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed its DevTools pipe: "
                                   + self.log.read_text()[-2000:])
            self._buffer += chunk
        message, _, self._buffer = self._buffer.partition(b"\0")
        return json.loads(message)

    def evaluate(self, expression: str):
        result = self.call("Runtime.evaluate", self.target_session, expression=expression,
                           returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression: str, seconds: float = 60.0) -> None:
        end = time.monotonic() + seconds
        while not self.evaluate(expression):
            if time.monotonic() > end:
                errors = [line for line in self.log.read_text().splitlines()
                          if "Uncaught" in line]
                raise TimeoutError(f"{expression} still false after {seconds} s {errors}")
            time.sleep(0.1)

    def screenshot(self) -> np.ndarray:
        """The page's pixels (RGB, 0–1) without the overlays (the heading, the control bar),
        once two more animation frames have been drawn."""
        import matplotlib.image

        self.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        data = self.call("Page.captureScreenshot", self.target_session, format="png")["data"]
        image = matplotlib.image.imread(io.BytesIO(base64.b64decode(data)), format="png")
        return image[90:-60, :, :3]

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.call("Browser.close")
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._write)
        os.close(self._read)


@pytest.fixture
def browser(tmp_path: Path, request):
    """The replay page in a headless Chromium; the test skips, before the page is made, where
    there is none (looked up now) or no POSIX pipes."""
    binary = chromium()
    if binary is None or fcntl is None:
        pytest.skip("no chromium on PATH (Debian: apt-get install chromium), or no POSIX pipes")
    page = request.getfixturevalue("page")
    devtools = DevTools(binary, page.as_uri() + getattr(request, "param", ""), tmp_path)
    try:
        devtools.wait_for("window.replay !== undefined && replay.state.shown > 0")
        yield devtools
    finally:
        devtools.close()


def drawn(image: np.ndarray) -> None:
    """WebGL drew the scene: many shades (floor, arm, paths), and the POI's red."""
    assert np.unique((255 * image).astype(np.uint8).reshape(-1, 3), axis=0).shape[0] > 200
    red = (image[..., 0] > 0.6) & (image[..., 1] < 0.4) & (image[..., 2] < 0.4)
    assert red.sum() > 20


@pytest.mark.slow
def test_the_page_draws_the_scene_and_the_slider_moves_it(browser: DevTools) -> None:
    browser.evaluate("replay.pause(); replay.seek(30)")  # 0.5 s
    early = browser.screenshot()
    browser.evaluate("replay.seek(150)")  # 2.5 s
    late = browser.screenshot()
    drawn(early)
    drawn(late)
    assert (np.abs(early - late).max(axis=2) > 0.1).mean() > 0.001  # the arm, the trails


@pytest.mark.slow
def test_the_page_plays_by_itself(browser: DevTools) -> None:
    browser.evaluate("replay.seek(0); replay.play()")
    before = browser.evaluate("[replay.state.time, replay.state.shown]")
    first = browser.screenshot()
    time.sleep(1.5)
    after = browser.evaluate("[replay.state.time, replay.state.shown]")
    second = browser.screenshot()
    assert after[1] > before[1] and after[0] != before[0]  # new frames, the clock moved
    assert (np.abs(first - second).max(axis=2) > 0.1).mean() > 0.0005
    assert "Uncaught" not in browser.log.read_text()


def _colour(image: np.ndarray, name: str) -> np.ndarray:
    """Pixels of the POI's red, the tool's blue or the forecast's green (shaded as drawn)."""
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    return {"poi": (r > 0.6) & (g < 0.4) & (b < 0.4),
            "tool": (b > 0.45) & (r < 0.3) & (b > g + 0.1),
            "forecast": (g > 0.45) & (r < 0.4) & (b < 0.45) & (g > r + 0.15)}[name]


@pytest.mark.slow
@pytest.mark.parametrize("browser", ["#paused"], indirect=True)
def test_the_first_view_shows_the_poi_the_tool_and_the_forecasts_shape(
        browser: DevTools) -> None:
    """Opened as it is (paused to hold the frame): the follow view, after the settling, with
    the POI, the tool and the forecast each in its own colour, unhidden by the arm, apart, and
    the forecast a sixth of the view tall or wide at least."""
    state = browser.evaluate("[replay.state.view, replay.state.time, replay.state.playing]")
    assert state[0] == "follow" and state[1] >= 1.0 and state[2] is False  # settling: 1 s
    image = browser.screenshot()
    spots = {k: np.argwhere(_colour(image, k)) for k in ("poi", "tool", "forecast")}
    assert all(len(v) > 15 for v in spots.values()), {k: len(v) for k, v in spots.items()}
    poi, tool = spots["poi"].mean(axis=0), spots["tool"].mean(axis=0)
    assert np.linalg.norm(poi - tool) > 6  # apart [px]
    extent = np.ptp(spots["forecast"], axis=0)
    assert max(extent[0] / image.shape[0], extent[1] / image.shape[1]) > 1 / 6


@pytest.mark.slow
def test_the_page_says_its_options_in_its_help(browser: DevTools) -> None:
    assert browser.evaluate("document.getElementById('help').hidden") is True
    browser.evaluate("document.getElementById('help-button').click()")
    text = browser.evaluate("document.getElementById('help').innerText")
    assert browser.evaluate("document.getElementById('help').hidden") is False
    for option in ("#t=2.5", "&paused", "&path", "&arm", "follow", "space bar"):
        assert option in text, option


def test_the_views_look_from_the_side_away_from_the_arm() -> None:
    """A path in the x-z plane, the forearm going up from the tool: the camera is on the path's
    normal side away from the forearm, tilted below."""
    from rhmpc.report.replay import view_direction

    t = np.linspace(0, 1, 50)
    path = np.c_[np.cos(6 * t), 0.001 * t, np.sin(6 * t)] * 1e-3
    d = view_direction(path, np.zeros(3), np.array([0.0, 0.1, 0.2]))
    assert d @ np.array([0.0, 0.1, 0.2]) < 0 and np.linalg.norm(d) == pytest.approx(1.0)
    assert abs(d[1]) > abs(d[0])  # mostly along the path's normal (y)


def test_chromium_is_looked_up_when_a_test_runs(tmp_path: Path, monkeypatch) -> None:
    """A Chromium installed after the tests were collected is found (a stand-in on PATH)."""
    monkeypatch.setenv("PATH", str(tmp_path))
    assert chromium() is None
    stand_in = tmp_path / "chromium"
    stand_in.write_text("#!/bin/sh\n")
    stand_in.chmod(0o755)
    assert chromium() == str(stand_in)
