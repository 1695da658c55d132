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

Only the run's processes can command: the key (:mod:`.wire.key`) reaches the controller through
an inherited pipe and the others in memory, never a command line or the environment, and every
message is sealed with it. The deployment supervises its parts: a part that dies, or a
controller whose supervisor stopped the run (the tool off the POI, deadlines missed), stops
every process in the safe state (the controller first, so that the robot's drivers brake) and
raises :class:`DeploymentError` with one line naming the part and the cause. Every child ends
with this process however it ends (the parent-death signal). The tool's positions the robot
logged are scored where the POI was measured, as the in-process run is.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.control.reference import LATENCY_CAP, embed3
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.assembly import build_run
from rhmpc.runtime import host, processes
from rhmpc.runtime.build import build_controller
from rhmpc.runtime.wire import WORKSPACE_RADIUS, Bounds, bind, new_key, write_key
from rhmpc.sim.loop.metrics import MeasuredScore
from rhmpc.tuning.workers import program_dies_with_parent

__all__ = ["GRACE_S", "DeploymentError", "SilSettings", "run_sil"]

#: Seconds from a stop request to SIGKILL.
GRACE_S = 2.0
#: The run's epoch lies this far after the processes start [s].
STARTUP_S = 2.0
#: What the controller program's exit statuses mean.
_CONTROLLER_EXITS = {1: "was stopped by a signal", 2: "refused its command line"}


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
        had no reading of their own (20 %: the robot's drivers hold a late torque for a tick,
        and a shared host's stalls of tens of milliseconds, measured on a 2-processor virtual
        machine, cost up to a tenth of a second now and then without leaving the POI; a host
        that loses a fifth of every second does not run the controller in time, and the tool
        bounds catch what that costs sooner).
    """

    priority: int = 80
    cpu: int | None = None
    internal: bool = True
    port: int | None = None
    workspace_radius: float = WORKSPACE_RADIUS
    tool_bound: float = 5e-3
    rms_bound: float = 1e-3
    miss_rate: float = 0.2

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


class DeploymentError(RuntimeError):
    """A part of the deployment failed or hung (the message says which, on one line)."""


class _Stopped(KeyboardInterrupt):
    """SIGTERM during a run: stopped like Ctrl-C."""


def _on_sigterm(*_) -> None:
    raise _Stopped


@dataclass
class _Part:
    """A child process of the run and the part it plays."""

    name: str
    child: subprocess.Popen | multiprocessing.Process

    @property
    def code(self) -> int | None:
        """Its exit status (negative: the signal that ended it), None while it runs."""
        if isinstance(self.child, subprocess.Popen):
            return self.child.poll()
        return None if self.child.is_alive() else self.child.exitcode

    def stop(self) -> None:
        if self.code is None:
            self.child.terminate()

    def kill(self) -> None:
        if self.code is None:
            self.child.kill()

    def reap(self) -> None:
        if isinstance(self.child, subprocess.Popen):
            self.child.wait()
        else:
            self.child.join()


class _Group:
    """The run's parts: started, supervised and stopped together, the controller first."""

    def __init__(self) -> None:
        self.parts: list[_Part] = []

    def spawn(self, name: str, command: list[str], fds: tuple[int, ...] = ()) -> None:
        child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                 text=True, pass_fds=fds, preexec_fn=program_dies_with_parent)
        self.parts.append(_Part(name, child))

    def fork(self, name: str, target, *args) -> None:
        child = multiprocessing.get_context("fork").Process(
            target=processes.run_part, args=(name, target, *args, os.getpid()), name=name)
        child.start()
        self.parts.append(_Part(name, child))

    def failed(self) -> _Part | None:
        """The first part that ended with a failure (the host probe's own is not one)."""
        return next((p for p in self.parts if p.name != "host probe" and p.code not in (None, 0)),
                    None)

    def running(self) -> bool:
        return any(p.code is None for p in self.parts)

    def stop(self) -> None:
        """The controller first (its silence brings the robot's drivers to their safe state
        after their watchdog), the others once they braked; SIGKILL after :data:`GRACE_S`."""
        for part in self.parts:
            if part.name == "controller":
                part.stop()
        time.sleep(2 * processes.WATCHDOG_TICKS * 0.5e-3)
        for part in self.parts:
            part.stop()
        deadline = time.monotonic() + GRACE_S
        while self.running() and time.monotonic() < deadline:
            time.sleep(0.02)
        for part in self.parts:
            part.kill()
            part.reap()


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
        group, previous = _Group(), signal.signal(signal.SIGTERM, _on_sigterm)
        try:
            _start(group, plan, role, sockets)
            say(f"{duration:g} s in real time ({len(group.parts)} processes)")
            failed = _supervise(group, STARTUP_S + duration + 30.0)
        finally:
            group.stop()
            signal.signal(signal.SIGTERM, previous)
        if failed is not None:
            refusals = plan.allowed.refusals()
            refused = "; this host refused " + ", ".join(refusals) if refusals else ""
            raise DeploymentError(_cause(failed, role, folder, duration) + refused)
        documents, arrays, q, host_latency = _collect(folder, host_tool(group), plan.config)
    score = _score(plan.run, q, documents["predictor"]["outliers"])
    return report(plan.config, plan.built, plan.settings.internal, documents, arrays,
                  host_latency, score, plan.in_process, (load_before, os.getloadavg()))


def host_tool(group: _Group) -> str:
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
                              for n in ("controller", "predictor", "robot")))
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


def _start(group: _Group, plan: _Deployment, role: processes.Role, sockets: dict) -> None:
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
    group.fork("robot", processes.robot, run, _with(role, top - 10, fifo), sockets["robot"])
    group.fork("predictor", processes.predictor, run, _with(role, 0, False),
               sockets["predictor"])
    group.fork("sensor", processes.sensor, run, _with(role, top - 20, fifo), sockets["sensor"])


def _with(role: processes.Role, priority: int, fifo: bool) -> processes.Role:
    """The role at SCHED_FIFO ``priority`` (at least 1: above every process of the default
    scheduler), or on the default scheduler."""
    return dataclasses.replace(role, priority=max(priority, 1) if fifo else 0)


def _supervise(group: _Group, seconds: float) -> _Part | None:
    """Watch the parts until every one has ended (None) or one failed or hung (that part)."""
    deadline = time.monotonic() + seconds
    while group.running():
        failed = group.failed()
        if failed is not None:
            return failed
        if time.monotonic() > deadline:
            return next(p for p in group.parts if p.code is None)
        time.sleep(0.05)
    return group.failed()


def _cause(part: _Part, role: processes.Role, folder: Path, duration: float) -> str:
    """One line: which part, what happened, when."""
    at = max(0.0, (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - role.epoch_ns) * 1e-9)
    code = part.code
    if code is None:
        what = "hung (still running after the run's end)"
    elif code < 0:
        what = f"died ({signal.Signals(-code).name})"
    elif part.name == "controller" and code == 3:
        doc = io.read_json(folder / "controller.json", track=False)
        what = f"stopped the run: {doc.get('stopped', 'its supervisor')}"
    elif part.name == "controller":
        err = part.child.stderr.read().strip().splitlines() if part.child.stderr else []
        what = f"{_CONTROLLER_EXITS.get(code, f'failed (exit {code})')}" + \
            (f": {err[-1]}" if err else "")
    else:
        fault = folder / f"{part.name}.fault"
        what = "failed: " + (io.read_text(fault).strip() if fault.is_file() else f"exit {code}")
    return (f"the {part.name} {what} at {min(at, duration):.1f} s of the {duration:g}-s run; "
            "every part stopped in the safe state")


def _collect(folder: Path, tool: str, config: RunConfig):
    """The parts' documents, the controller's timing arrays, the robot's log and the probe's."""
    documents = {name: io.read_json(folder / f"{name}.json", track=False)
                 for name in ("controller", "robot", "predictor", "sensor")}
    arrays = {name: host.read_int64(folder / f"controller.{name}")
              for name in ("wake", "work", "step", "s2t")}
    q = np.load(BytesIO(io.read_bytes(folder / "robot_q.npy", track=False)))
    return documents, arrays, q, host.read_probe(folder / "host", tool, config.loop.Ts)


def _score(run, q: np.ndarray, outliers: list[float]) -> dict:
    """The tool after each tick against the POI where it was measured (a recording: at its
    samples' instants) or at every tick (a synthetic motion), as the in-process run."""
    loop = run.config.loop
    ticks = loop.ticks
    done = np.isfinite(q).all(axis=1)
    ee = np.full((ticks, 3), np.nan)
    ee[done] = [run.robot.ee_position(row) for row in q[done]]
    if run.measured is not None:
        t, z = run.measured
        placed = run.anchor + embed3(np.asarray(z, dtype=float).reshape(len(t), -1)
                                     - run.truth.center)
    else:
        t = (np.arange(ticks) + 1) * loop.Ts
        placed = run.anchor + embed3(run.truth.window(1, ticks + 1))
    score = MeasuredScore(t, placed, loop.settling_ticks * loop.Ts, ticks * loop.Ts, loop.Ts)
    score.add(0, ee)
    score.fold(outliers)
    return score.result()


def _packets(documents: dict) -> dict:
    """Per kind: sent, and what its receivers took, lost and dropped."""
    controller, robot, predictor = (documents[k] for k in ("controller", "robot", "predictor"))
    sent = {"measured_cp": documents["sensor"]["sent"], "forecast_cp": predictor["forecasts"],
            "measured_js": controller["ticks"] + 1, "servo_jf": controller["ticks"]}
    out = {kind: {"sent": sent[kind], "received": controller["received"][kind],
                  "lost": controller["lost"][kind]}
           for kind in ("measured_cp", "forecast_cp", "measured_js")}
    out["servo_jf"] = {"sent": sent["servo_jf"], "received": robot["arrivals"]["received"][
        "servo_jf"], "lost": robot["arrivals"]["lost"]["servo_jf"]}
    out["measured_cp_at_predictor"] = {"sent": sent["measured_cp"],
                                       "received": predictor["arrivals"]["received"][
                                           "measured_cp"],
                                       "lost": predictor["arrivals"]["lost"]["measured_cp"]}
    return out


def report(config: RunConfig, built, internal: bool, documents: dict, arrays: dict,
           host_latency: dict, score: dict, in_process: dict, load: tuple) -> dict:
    """The run's report: timing, packets, drops, the score beside the in-process one."""
    controller, robot = documents["controller"], documents["robot"]
    fallback = f"the controller's own {built.internal} RLS" if internal else "hold"
    return {
        "recording": config.data or config.scenario, "predictor": config.predictor,
        "duration_s": config.loop.duration, "ticks": controller["ticks"],
        "deadline_misses": controller["deadline_misses"],
        "wakeup_latency_us": host.percentiles(arrays["wake"] * 1e-3),
        "host_wakeup_latency_us": host_latency,
        "tick_work_us": host.percentiles(arrays["work"] * 1e-3),
        "controller_step_us": host.percentiles(arrays["step"] * 1e-3),
        "sensor_to_torque_ms": {k: None if v is None else round(v * 1e-3, 3) for k, v in
                                host.percentiles(arrays["s2t"] * 1e-3).items()},
        "packets": _packets(documents),
        "dropped": {"controller": controller["dropped"],
                    "predictor": documents["predictor"]["arrivals"]["dropped"],
                    "robot": robot["arrivals"]["dropped"]},
        "stale_encoders": controller["stale_encoders"],
        "torques_missed": robot["torques_missed"], "torques_late": robot["torques_late"],
        "robot_safe_state_ticks": robot["safe_state_ticks"],
        "forecasts_rejected": controller["forecasts_rejected"],
        "forecast_fallback": fallback,
        "points_served_ticks": controller["served"],
        "rms_error_mm": score["rms_error_mm"], "max_error_mm": score["max_error_mm"],
        "scored_samples": score["scored_samples"],
        "in_process_rms_error_mm": in_process["rms_error_mm"],
        "supervisor_tool_error_mm": controller["tool_error_mm"],
        "fallbacks": controller["fallbacks"], "failures": controller["failures"],
        "predictor_forecast_ms": documents["predictor"]["forecast_ms"],
        "realtime": {"controller": controller["realtime"], "robot": robot["scheduling"],
                     "sensor": documents["sensor"]["scheduling"],
                     "predictor": documents["predictor"]["scheduling"]},
        "host_load": {"before": [round(v, 2) for v in load[0]],
                      "after": [round(v, 2) for v in load[1]], "cpus": os.cpu_count()},
    }
