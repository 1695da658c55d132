"""One deployment on one machine in real time: every process of a run, supervised.

:func:`run_sil` builds the run (:func:`rhmpc.experiment.assembly.build_run`), runs the
in-process simulation of the same settings for comparison, builds the controller's program
(:mod:`.build`), asks the host what it permits (:func:`rhmpc.runtime.host.permits`, said up
front), makes the run's key and binds every port, then starts, on the run's clock (its epoch a
moment ahead):

- the **controller** (the exported C: real time where permitted, its own supervisor) and beside
  it the **host probe** (:mod:`rhmpc.runtime.host`),
- the **robot**, the **predictor** and the **sensor** (:mod:`.processes`), each a process of its
  own holding the run, on the other processors.

The parts are supervised by :mod:`rhmpc.runtime.supervisor` and reported by
:mod:`rhmpc.runtime.report`. Only the run's processes can command: the key
(:mod:`rhmpc.runtime.wire.key`) reaches the controller through an inherited pipe and the others in
memory, never a command line or the environment, and every message is sealed with it. The
deployment supervises its parts: a part that dies, or a controller whose supervisor stopped the run
(the tool off the POI, deadlines missed), stops every process in the safe state (the controller
first, so that the robot's drivers brake) and raises :class:`DeploymentError` with one line naming
the part and the cause. Every child ends with this process however it ends (the parent-death
signal). The tool's positions the robot logged are scored where the POI was measured, as the
in-process run is.
"""

from __future__ import annotations

import dataclasses
import math
import os
import signal
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from rhmpc.control.reference import LATENCY_CAP
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.assembly import build_run
from rhmpc.runtime import host, processes, ros2
from rhmpc.runtime.build import build_controller
from rhmpc.runtime.report import collect, report, score
from rhmpc.runtime.supervisor import GRACE_S, Group, cause, supervise
from rhmpc.runtime.wire import WORKSPACE_RADIUS, Bounds, bind, new_key, write_key

__all__ = ["GRACE_S", "DeploymentError", "SilSettings", "run_sil"]

#: The run's epoch lies this far after the processes start [s].
STARTUP_S = 2.0


@dataclass(frozen=True)
class SilSettings:
    """How the processes run, and the bounds of the deployment's supervisor.

    Attributes
    ----------
    priority : int
        SCHED_FIFO priority of the controller and of the host probe, where permitted; the robot
        runs 10 below it, the sensor 20 below (at least 1); the predictor on the default
        scheduler.
    cpu : int or None
        The processor the controller and the probe are pinned to (default: the last one this
        process may use).
    internal : bool
        The controller's own predictor learns from the samples and serves when forecasts stop;
        False: forecasts alone drive it, a lost one holds the last points.
    port : int or None
        The controller's UDP port on loopback, the predictor's ``port + 1``, the robot's
        ``port + 2``; None: any free ones.
    workspace_radius : float
        How far from the POI's registration a sample or a forecast may lie [m]
        (:data:`~rhmpc.runtime.wire.WORKSPACE_RADIUS`).
    tool_bound : float
        The supervisor stops the run when the tool lies farther than this from a sample of the
        POI, at the sample's instant, after the run's settling time [m]. 5 mm: ten times the
        0.1–0.25 mm RMS error the task asks for (Tuna et al. 2013), beyond any beat's transient.
    rms_bound : float
        ... or when the RMS of those distances over one second of samples exceeds this [m]
        (1 mm: four times the task's worst acceptable RMS).
    miss_rate : float
        ... or when more than this share of the ticks of one second missed their deadline or
        had no reading of their own within the observer's ``max_delay`` (20 %: the robot's
        drivers hold a late torque for a tick, and a shared host's stalls of tens of
        milliseconds, measured on a 2-processor virtual machine, cost up to a tenth of a second
        now and then without leaving the POI; a host that loses a fifth of every second does
        not run the controller in time, and the tool bounds catch what that costs sooner).
    tracker, console : str or None
        The ROS 2 topic of a tracker's samples (PoseStamped or PoseArray), the namespace of an
        arm over ROS 2 (``/PSM1``): a bridge takes the sensor's, the robot's place
        (:mod:`rhmpc.runtime.ros2`); None: the run's sensor, the simulator.
    allow_unauthenticated : bool
        A console over ROS 2 is refused without it: ROS 2 without SROS2 authenticates nothing.
    """

    priority: int = 80
    cpu: int | None = None
    internal: bool = True
    port: int | None = None
    workspace_radius: float = WORKSPACE_RADIUS
    tool_bound: float = 5e-3
    rms_bound: float = 1e-3
    miss_rate: float = 0.2
    tracker: str | None = None
    console: str | None = None
    allow_unauthenticated: bool = False

    def __post_init__(self) -> None:
        if not 1 <= self.priority <= 99:
            raise ValueError(f"priority must be 1 … 99 (SCHED_FIFO), got {self.priority}")
        if self.cpu is not None and self.cpu not in os.sched_getaffinity(0):
            raise ValueError(f"cpu {self.cpu} is not one this process may run on "
                             f"({sorted(os.sched_getaffinity(0))})")
        if self.port is not None and not 1024 <= self.port <= 65533:
            raise ValueError(f"port must be 1024 … 65533 (three ports from it), got {self.port}")
        for name in ("workspace_radius", "tool_bound", "rms_bound", "miss_rate"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        names = ros2.checked(self.tracker, self.console, self.allow_unauthenticated)
        object.__setattr__(self, "tracker", names[0])
        object.__setattr__(self, "console", names[1])


class DeploymentError(RuntimeError):
    """A part of the deployment failed or hung (the message says which, on one line)."""


class _Stopped(KeyboardInterrupt):
    """SIGTERM during a run: stopped like Ctrl-C."""


def _on_sigterm(*_) -> None:
    raise _Stopped


def _bind_ports(settings: SilSettings) -> dict:
    """The run's sockets on loopback, bound before any process starts (no port can be taken
    between a choice and a bind). :class:`UsageError` names a port already in use."""
    names = ("controller", "predictor", "robot", "sensor")
    sockets = {}
    try:
        for i, name in enumerate(names):
            port = 0 if settings.port is None or name == "sensor" else settings.port + i
            sockets[name] = bind(port)
    except OSError as exc:
        for sock in sockets.values():
            sock.close()
        raise UsageError(f"{exc.strerror}: give another --port, or none for any free ports"
                         ) from None
    return sockets


@dataclass(frozen=True)
class _Deployment:
    """A run ready to deploy: its settings, the built run and program, the host's answers."""

    config: RunConfig
    settings: SilSettings
    run: object  # rhmpc.experiment.assembly's built run
    built: object  # rhmpc.runtime.build.BuiltController
    cpu: int
    allowed: host.Permits
    in_process: dict


def run_sil(config: RunConfig, settings: SilSettings = SilSettings(), progress=None) -> dict:
    """Run ``config`` as separate processes in real time; returns the report (:func:`report`).
    :class:`DeploymentError` when a part fails or the supervisor stops the run."""
    say = progress or (lambda text: None)
    ros2.require(settings.tracker, settings.console)  # first: a missing extra before any work
    say("the in-process simulation of the same settings")
    in_process = run_experiment(config)[1]
    run = build_run(config)
    say("the controller's program (export, CMake)")
    built = build_controller(config, run.clock.sensor_rate)
    cpu = settings.cpu if settings.cpu is not None else max(os.sched_getaffinity(0))
    allowed = host.permits(settings.priority, cpu)
    for refusal in allowed.refusals():
        say(f"this host does not permit {refusal}: the run goes on without it, and its "
            "supervisor stops it if the deadlines are missed")
    plan = _Deployment(config, settings, run, built, cpu, allowed, in_process)
    sockets = _bind_ports(settings)  # just before the processes: they inherit them
    try:
        return _deploy(plan, sockets, say)
    finally:
        for sock in sockets.values():
            sock.close()


def _deploy(plan: _Deployment, sockets: dict, say) -> dict:
    """The processes of the run on its clock, supervised; the report."""
    load_before, duration = os.getloadavg(), plan.config.loop.duration
    with tempfile.TemporaryDirectory(prefix="rhmpc-sil-") as tmp:
        folder = Path(tmp)
        role = _role(plan, sockets, folder)
        group, previous = Group(), signal.signal(signal.SIGTERM, _on_sigterm)
        try:
            _start(group, plan, role, sockets)
            say(f"{duration:g} s in real time ({len(group.parts)} processes)")
            failed = supervise(group, STARTUP_S + duration + 30.0)
        finally:
            group.stop()
            signal.signal(signal.SIGTERM, previous)
        if failed is not None:
            refusals = plan.allowed.refusals()
            refused = "; this host refused " + ", ".join(refusals) if refusals else ""
            raise DeploymentError(cause(failed, role, folder, duration) + refused)
        documents, arrays, q, host_latency = collect(folder, host_tool(group), plan.config)
        try:  # a tracker's bridge: the POI where the tracker measured it
            measured = ros2.taken(folder, plan.run) if plan.settings.tracker else plan.run.measured
        except ValueError as exc:
            raise DeploymentError(str(exc)) from None
    scored = score(plan.run, q, documents["predictor"]["outliers"], measured)
    return report(plan.config, plan.built, plan.settings.internal, documents, arrays,
                  host_latency, scored, plan.in_process, (load_before, os.getloadavg()))


def host_tool(group: Group) -> str:
    """The host probe's tool: cyclictest, or the controller's loop without its work."""
    probe = next(p for p in group.parts if p.name == "host probe")
    return "cyclictest" if "cyclictest" in str(probe.child.args[0]) else \
        "rhmpc probe (the controller's loop without its work)"


def _role(plan: _Deployment, sockets: dict, folder: Path) -> processes.Role:
    """What every part shares: the clock, the ports, the key, the bounds."""
    loop, robot, settings = plan.config.loop, plan.run.robot, plan.settings
    lower, upper = robot.position_limits
    bounds = Bounds(tuple(robot.torque_limit), tuple(lower), tuple(upper),
                    tuple(float(v) for v in plan.run.reference.center),
                    radius=settings.workspace_radius, max_age=LATENCY_CAP)
    ports = processes.Ports(*(sockets[n].getsockname()[1]
                              for n in ("controller", "predictor", "robot")),
                            bridge=sockets["sensor"].getsockname()[1] if settings.tracker else None)
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + int(STARTUP_S * 1e9)
    priority = settings.priority if plan.allowed.fifo is None else 0
    return processes.Role(epoch, loop.ticks, loop.Ts, ports, folder, new_key(), bounds,
                          priority, plan.cpu)


def _controller_command(plan: _Deployment, role: processes.Role, key_fd: int,
                        sock_fd: int) -> list[str]:
    """The controller program's command line: its key and socket inherited, its bounds."""
    settings, loop, reference = plan.settings, plan.config.loop, plan.run.reference
    command = [str(plan.built.program), "--key-file", f"/dev/fd/{key_fd}", "--socket-fd",
               str(sock_fd), "--epoch", str(role.epoch_ns), "--ticks", str(role.ticks),
               "--robot-port", str(role.ports.robot), "--cpu", str(role.controller_cpu),
               "--priority", str(settings.priority), "--out", str(role.folder / "controller"),
               "--radius", repr(settings.workspace_radius),
               "--settle", repr(loop.settling_ticks * loop.Ts),
               "--tool-bound", repr(settings.tool_bound), "--rms-bound",
               repr(settings.rms_bound), "--miss-rate", repr(settings.miss_rate),
               "--origin", *(repr(float(v)) for v in reference.origin),
               "--center", *(repr(float(v)) for v in reference.center)]
    return command + ([] if settings.internal else ["--no-internal"])


def _start(group: Group, plan: _Deployment, role: processes.Role, sockets: dict) -> None:
    """Every part, on the run's clock: the controller (its key through a pipe it inherits),
    the host probe, then the robot, the predictor and the sensor (forked, key in memory)."""
    read, write = os.pipe()
    write_key(write, role.key)
    sock_fd = sockets["controller"].fileno()
    try:
        group.spawn("controller", _controller_command(plan, role, read, sock_fd),
                    (read, sock_fd))
    finally:
        os.close(read)
    probe, _ = host.probe_command(
        plan.built.program, epoch_ns=role.epoch_ns, ticks=role.ticks, Ts=role.Ts,
        cpu=role.controller_cpu, priority=plan.settings.priority, out=role.folder / "host",
        phase_ns=round(role.Ts * 5e8), allowed=plan.allowed)
    group.spawn("host probe", probe)
    fifo, top, run = plan.allowed.fifo is None, plan.settings.priority, plan.run
    robot = ros2.console_part(plan.settings.console) or ("robot", processes.robot)
    sensor = ros2.tracker_part(plan.settings.tracker) or ("sensor", processes.sensor)
    group.fork(*robot[:2], run, _with(role, top - 10, fifo), sockets["robot"], *robot[2:])
    group.fork("predictor", processes.predictor, run, _with(role, 0, False),
               sockets["predictor"])
    group.fork(*sensor[:2], run, _with(role, top - 20, fifo), sockets["sensor"], *sensor[2:])


def _with(role: processes.Role, priority: int, fifo: bool) -> processes.Role:
    """The role at SCHED_FIFO ``priority`` (at least 1: above every process of the default
    scheduler), or on the default scheduler."""
    return dataclasses.replace(role, priority=max(priority, 1) if fifo else 0)


