"""`rhmpc sil` with its bridges to ROS 2, against a foreign DDS participant in this process that
plays a ROS 2 tracker and console.

The participant is set up as a ROS 2 node on Cyclone DDS sets itself up, with no code of the
bridges: DDS topics ``rt/…``, the ROS 2 type names, rclpy's default QoS (reliable, keep the
last 10) for its publishers and subscribers. It replays the shipped phantom's POI as
``geometry_msgs/PoseStamped`` at the instants the run's sensor would deliver it (the run's
instant 0 read from the bridge's status), reads the forecasts (``nav_msgs/Path``) and the
status, and, as a console, answers each ``servo_jf`` with the simulated arm's ``measured_js``.
Every DDS packet stays on loopback (a configuration of Cyclone DDS without multicast) and on a
domain of this process's own.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from rhmpc.compiled import compiler
from tests.rhmpc.runtime.test_sil import _rhmpc, outcome

cyclonedds = pytest.importorskip("cyclonedds", reason="the ROS 2 bridges need rhmpc[ros2]")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("cmake") is None or compiler() is None,
                       reason="cmake or a C compiler missing"),
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc"),
]

from cyclonedds.core import Listener, Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402

from rhmpc.runtime.ros2 import messages as m  # noqa: E402

ARGS = ["--data", "hamlyn-phantom", "--poi", "4", "--predictor", "ridge", "--priority", "10"]
#: rclpy's default QoS (rmw_qos_profile_default), as a ROS 2 node asks for it.
NODE_QOS = Qos(Policy.Reliability.Reliable(max_blocking_time=100_000_000),
               Policy.History.KeepLast(10), Policy.Durability.Volatile)
#: Cyclone DDS on loopback only: no multicast, discovery by unicast to this host's ports.
LOOPBACK = ("<CycloneDDS><Domain Id='any'><General><Interfaces><NetworkInterface "
            "address='127.0.0.1'/></Interfaces><AllowMulticast>false</AllowMulticast></General>"
            "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>20"
            "</MaxAutoParticipantIndex><Peers><Peer address='127.0.0.1'/></Peers></Discovery>"
            "</Domain></CycloneDDS>")


@pytest.fixture
def ros2_domain(tmp_path: Path, monkeypatch) -> None:
    """This process and the runs it starts on a domain of their own, on loopback."""
    (tmp_path / "cyclonedds.xml").write_text(LOOPBACK)
    monkeypatch.setenv("CYCLONEDDS_URI", (tmp_path / "cyclonedds.xml").as_uri())
    monkeypatch.setenv("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))


def _run(argv: list[str]):
    """The run the deployment builds from ``argv``: its sensor's deliveries and its plant."""
    from rhmpc.cli import build_parser
    from rhmpc.cli.simulate import config_from_args
    from rhmpc.experiment.assembly import build_run

    return build_run(config_from_args(build_parser("sil").parse_args(["sil", *argv])))


def _deliveries(run) -> list[tuple[float, float, np.ndarray]]:
    """(arrival, stamp, POI) of every sample the run's sensor delivers [s, s, m]."""
    from rhmpc.positions import embed3
    from rhmpc.sim.loop.closed_loop import Refreshes

    loop = run.config.loop
    refreshes, out = Refreshes(run.stream, loop, run.clock, run.points), []
    while refreshes.next < loop.ticks:
        tick = int(refreshes.next)
        out += [(tick * loop.Ts, stamp, np.ravel(embed3(z)))
                for z, stamp, _ in refreshes.due(tick) if z is not None]
    return out


class _Call(Listener):
    def __init__(self, call) -> None:
        super().__init__()
        self.call = call

    def on_data_available(self, reader) -> None:
        for sample in reader.take(16):
            if getattr(sample, "sample_info", None) is not None and sample.sample_info.valid_data:
                self.call(sample)


class Foreign:
    """A ROS 2 node's participant: a tracker on /tracker/poi, a reader of the forecasts and
    the status, and (:meth:`console`) an arm under /PSM1."""

    def __init__(self) -> None:
        self.dp = DomainParticipant(int(os.environ["ROS_DOMAIN_ID"]))
        self.epoch: int | None = None
        self.statuses: list[tuple[str, int, str]] = []
        self.paths: list[m.Path] = []
        self.keep = [self._reader("rt/rhmpc/status", m.DiagnosticStatus, self._status),
                     self._reader("rt/rhmpc/forecast_cp", m.Path, self.paths.append)]
        self.poses = self._writer("rt/tracker/poi", m.PoseStamped)

    def _reader(self, topic: str, cls: type, call) -> DataReader:
        return DataReader(self.dp, Topic(self.dp, topic, cls), NODE_QOS, listener=_Call(call))

    def _writer(self, topic: str, cls: type) -> DataWriter:
        return DataWriter(self.dp, Topic(self.dp, topic, cls), NODE_QOS)

    def _status(self, status: m.DiagnosticStatus) -> None:
        values = {kv.key: kv.value for kv in status.values}
        sec, nanosec = values["epoch"].split(".")
        self.epoch = int(sec) * 1_000_000_000 + int(nanosec)
        self.statuses.append((status.name, status.level, status.message, values))

    def wait_for_epoch(self, seconds: float = 120.0) -> int:
        deadline = time.monotonic() + seconds
        while self.epoch is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert self.epoch is not None, "no status from the bridge"
        return self.epoch

    def _sleep_until(self, ns: int) -> None:
        while (left := ns - time.clock_gettime_ns(time.CLOCK_REALTIME)) > 0:
            time.sleep(min(left * 1e-9, 0.1))

    def track(self, deliveries) -> None:
        """Each sample at its arrival, stamped with its instant (ROS time)."""
        epoch = self.wait_for_epoch()
        for arrival, stamp, poi in deliveries:
            self._sleep_until(epoch + round(arrival * 1e9))
            self.poses.write(m.PoseStamped(
                m.Header(m.time_of(epoch + round(stamp * 1e9)), "tracker"), m.pose_at(poi)))

    def console(self, run) -> threading.Thread:
        """The simulated arm behind its drivers, answering each tick's torque with the next
        tick's reading (the simulator's rule)."""
        from rhmpc.runtime.processes import Drivers
        from rhmpc.runtime.ros2.console import joint_names

        names, Ts = joint_names(run.robot), run.config.loop.Ts
        drivers, readings = Drivers(run.robot, Ts), self._writer("rt/PSM1/measured_js",
                                                                  m.JointState)
        state = {"tick": -1, "reading": run.plant.encoders()}

        def send(tick: int) -> None:
            readings.write(m.JointState(m.Header(m.time_of(self.epoch + round(tick * Ts * 1e9))),
                                        names, [float(v) for v in state["reading"]]))

        def answer(torque: m.JointState) -> None:
            tick = round((m.nanoseconds(torque.header.stamp) - self.epoch) * 1e-9 / Ts)
            for i in range(state["tick"] + 1, tick + 1):  # a missed tick holds the last torque
                command = np.array(torque.effort) if i == tick else None
                run.plant.step(drivers.torque(command, state["reading"]))
                state["reading"] = run.plant.encoders()
            state["tick"] = max(state["tick"], tick)
            send(tick + 1)

        self.keep.append(self._reader("rt/PSM1/servo_jf", m.JointState, answer))

        def first() -> None:
            self._sleep_until(self.wait_for_epoch() - round(Ts * 5e8))
            send(0)

        thread = threading.Thread(target=first, daemon=True)
        thread.start()
        return thread


@contextlib.contextmanager
def _drivers_priority(priority: int):
    """This process's threads (the arm's DDS reader among them) under SCHED_FIFO at
    ``priority`` where the host permits, as a console's drivers run; as before afterwards."""
    def threads() -> list[int]:
        return [int(t) for t in os.listdir("/proc/self/task")]

    before = {}
    for tid in threads():
        with contextlib.suppress(OSError):
            before[tid] = (os.sched_getscheduler(tid), os.sched_getparam(tid))
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
    try:
        yield
    finally:
        for tid in threads():
            policy, param = before.get(tid, (os.SCHED_OTHER, os.sched_param(0)))
            with contextlib.suppress(OSError):
                os.sched_setscheduler(tid, policy, param)


def _play(argv: list[str], console: bool = False) -> tuple[int, dict | None, str, Foreign]:
    foreign, run = Foreign(), _run(argv)
    extra = ["--tracker", "ros2:/tracker/poi"]
    if console:
        foreign.console(run)
        extra += ["--console", "ros2:/PSM1", "--allow-unauthenticated"]
    proc = _rhmpc("sil", *argv, *extra, "--json")
    with _drivers_priority(int(argv[argv.index("--priority") + 1])) if console else \
            contextlib.nullcontext():
        tracker = threading.Thread(target=foreign.track, args=(_deliveries(run),), daemon=True)
        tracker.start()
        code, report, err = outcome(proc)
    return code, report, err, foreign


@pytest.fixture(scope="module")
def wire_run() -> dict:
    """The same 8 s over the authenticated wire alone (the simulated robot, the sensor)."""
    code, report, _ = outcome(_rhmpc("sil", *ARGS, "--duration", "8", "--json"))
    assert code == 0, "the UDP run stopped"
    return report


def test_a_ros2_tracker_tracks_as_the_wire_does(ros2_domain, wire_run) -> None:
    """8 s of the phantom's POI from a ROS 2 tracker: every sample sent, a Path per
    forecast, the status from waiting to ended, and the RMS within 10 % of the UDP run's."""
    argv = [*ARGS, "--duration", "8"]
    code, report, err, foreign = _play(argv)
    assert code == 0, err[-2000:]
    bridge = report["ros2"]["tracker"]
    assert bridge["type"] == "geometry_msgs/msg/PoseStamped" and bridge["frame_id"] == "tracker"
    assert bridge["received"] == len(_deliveries(_run(argv))) == bridge["sent"]
    assert report["packets"]["measured_cp"]["received"] == bridge["sent"]
    assert bridge["forecasts_published"] == report["packets"]["forecast_cp"]["sent"] > 0
    time.sleep(0.5)
    assert len(foreign.paths) == bridge["forecasts_published"]
    assert all(len(p.poses) >= 4 and p.header.frame_id == "tracker" for p in foreign.paths)
    messages = [s[2] for s in foreign.statuses]
    assert {"waiting for the run's start", "running", "ended"} <= set(messages)
    rms, ref = report["rms_error_mm"], wire_run["rms_error_mm"]
    assert abs(rms / ref - 1) <= 0.10, (rms, ref)


def test_a_ros2_console_tracks_as_the_wire_does(ros2_domain, wire_run) -> None:
    """8 s with both bridges, the arm over ROS 2 answering each torque with its next reading
    (two DDS hops in Python a tick, so that readings often come a tick or more late): the
    torques went out as JointState by the arm's joint names, every reading reached the
    controller, the late ones were fused into their own ticks, and the RMS is within 10 % of
    the UDP run's."""
    code, report, err, _ = _play([*ARGS, "--duration", "8"], console=True)
    assert code == 0, err[-2000:]
    console = report["ros2"]["console"]
    assert console["joints"] == ["yaw", "shoulder", "elbow"]
    assert console["torques_published"] > 0.9 * report["ticks"]
    assert console["readings"]["sent"] == console["readings"]["received"] > 0.9 * report["ticks"]
    assert 0 <= console["readings"]["sent"] - report["packets"]["measured_js"]["received"] <= 2
    late = report["late_readings"]
    assert 0 < late["max_delay_ticks"] <= 40 and late["fused"] > 0
    rms, ref = report["rms_error_mm"], wire_run["rms_error_mm"]
    assert abs(rms / ref - 1) <= 0.10, (rms, ref)
