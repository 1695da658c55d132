"""One deployment on one machine in real time: every process of a run, and what it measured.

:func:`run_sil` builds the run (:func:`rhmpc.experiment.assembly.build_run`), runs the
in-process simulation of the same settings for comparison, builds the controller's program
(:mod:`.build`) and starts, on the run's clock (its epoch a moment ahead):

- the **controller** (the exported C at 2 kHz: real time where permitted) and beside it the
  **host probe** (:mod:`rhmpc.runtime.host`),
- the **robot**, the **predictor** and the **sensor** (:mod:`.processes`), each a process of its
  own holding the run, on the other processors.

They end by themselves after the run's ticks. Ctrl-C or SIGTERM stops every one of them
(SIGTERM, then SIGKILL after :data:`GRACE_S`), and each ends with the run anyway (its
parent-death signal). The tool's positions the robot logged are scored where the POI was
measured, as the in-process run is (:class:`rhmpc.sim.loop.metrics.MeasuredScore`).
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import signal
import socket
import subprocess
import tempfile
import time
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.assembly import build_run
from rhmpc.positions import embed3
from rhmpc.runtime import host, processes
from rhmpc.runtime.build import build_controller
from rhmpc.sim.loop.metrics import MeasuredScore

__all__ = ["GRACE_S", "DeploymentError", "SilSettings", "run_sil"]

#: Seconds from a stop request to SIGKILL.
GRACE_S = 2.0
#: The run's epoch lies this far after the processes start [s].
STARTUP_S = 2.0


@dataclass(frozen=True)
class SilSettings:
    """How the processes run.

    Attributes
    ----------
    priority : int
        SCHED_FIFO priority of the controller and of the host probe, where permitted; the robot
        runs 10 below it, the sensor 20 below; the predictor on the default scheduler.
    cpu : int or None
        The processor the controller and the probe are pinned to (default: the last one this
        process may use).
    internal : bool
        The controller's own predictor learns from the samples and serves when forecasts stop;
        False: the last points hold.
    """

    priority: int = 80
    cpu: int | None = None
    internal: bool = True

    def __post_init__(self) -> None:
        if not 1 <= self.priority <= 99:
            raise ValueError(f"priority must be 1 … 99 (SCHED_FIFO), got {self.priority}")
        if self.cpu is not None and self.cpu not in os.sched_getaffinity(0):
            raise ValueError(f"cpu {self.cpu} is not one this process may run on "
                             f"({sorted(os.sched_getaffinity(0))})")


def _free_ports(n: int) -> list[int]:
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    for s in sockets:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in sockets]
    for s in sockets:
        s.close()
    return ports


class _Processes:
    """The children: started, waited for, and stopped together (SIGTERM, then SIGKILL)."""

    def __init__(self) -> None:
        self.children: list = []

    def spawn(self, command: list[str]) -> None:
        self.children.append(subprocess.Popen(command, stdout=subprocess.DEVNULL,
                                              stderr=subprocess.PIPE, text=True))

    def fork(self, target, *args) -> None:
        child = multiprocessing.get_context("fork").Process(target=target,
                                                             args=(*args, os.getpid()))
        child.start()
        self.children.append(child)

    @staticmethod
    def _alive(child) -> bool:
        return child.poll() is None if isinstance(child, subprocess.Popen) else child.is_alive()

    def wait(self, deadline: float) -> bool:
        """Wait until every child has ended (True) or ``deadline`` (monotonic [s]) passes."""
        while any(self._alive(c) for c in self.children):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.05)
        return True

    def stop(self) -> None:
        for child in self.children:
            if self._alive(child):
                child.terminate()
        if not self.wait(time.monotonic() + GRACE_S):
            for child in self.children:
                if self._alive(child):
                    child.kill()
        for child in self.children:
            child.wait() if isinstance(child, subprocess.Popen) else child.join()

    def failures(self) -> list[str]:
        out = []
        for child in self.children:
            if isinstance(child, subprocess.Popen):
                err = child.stderr.read().strip() if child.stderr else ""
                if child.returncode:
                    out.append(f"{Path(child.args[0]).name} exit {child.returncode}: {err[-200:]}")
            elif child.exitcode:
                out.append(f"{child.name} exit {child.exitcode}")
        return out


class DeploymentError(RuntimeError):
    """A process of the deployment failed or hung (the message says which, on one line)."""


class _Stopped(KeyboardInterrupt):
    """SIGTERM during a run: stopped like Ctrl-C."""


def _on_sigterm(*_) -> None:
    raise _Stopped


def run_sil(config: RunConfig, settings: SilSettings = SilSettings(), progress=None) -> dict:
    """Run ``config`` as separate processes in real time; returns the report (:func:`report`)."""
    say = progress or (lambda text: None)
    say("the in-process simulation of the same settings")
    in_process = run_experiment(config)[1]
    run = build_run(config)
    say("the controller's program (export, CMake)")
    built = build_controller(config, run.clock.sensor_rate)
    loop = config.loop
    cpu = settings.cpu if settings.cpu is not None else max(os.sched_getaffinity(0))
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="rhmpc-sil-") as tmp:
        folder = Path(tmp)
        ports = processes.Ports(*_free_ports(3))
        epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + int(STARTUP_S * 1e9)
        role = processes.Role(epoch, loop.ticks, loop.Ts, ports, folder, 0, cpu)
        probe, tool = host.probe_command(
            built.program, epoch_ns=epoch, ticks=loop.ticks, Ts=loop.Ts, cpu=cpu,
            priority=settings.priority, out=folder / "host", phase_ns=round(loop.Ts * 5e8))
        command = [str(built.program), "--epoch", str(epoch), "--ticks", str(loop.ticks),
                   "--port", str(ports.controller), "--robot-port", str(ports.robot),
                   "--cpu", str(cpu), "--priority", str(settings.priority),
                   "--out", str(folder / "controller"),
                   "--origin", *(repr(float(v)) for v in run.reference.origin),
                   "--center", *(repr(float(v)) for v in run.reference.center)]
        if not settings.internal:
            command.append("--no-internal")
        group = _Processes()
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
        try:
            group.spawn(command)
            group.spawn(probe)
            group.fork(processes.robot, run, _with(role, settings.priority - 10))
            group.fork(processes.predictor, run, role)
            group.fork(processes.sensor, run, _with(role, settings.priority - 20))
            say(f"{loop.duration:g} s in real time ({len(group.children)} processes)")
            finished = group.wait(time.monotonic() + STARTUP_S + loop.duration + 30.0)
        finally:
            group.stop()
            signal.signal(signal.SIGTERM, previous)
        failed = group.failures()
        if not finished or failed:
            raise DeploymentError("the deployment did not finish: " + ("; ".join(failed) or
                                                                      "a process hung"))
        documents = {name: io.read_json(folder / f"{name}.json", track=False)
                     for name in ("controller", "robot", "predictor", "sensor")}
        arrays = {name: host.read_int64(folder / f"controller.{name}")
                  for name in ("wake", "work", "step", "s2t")}
        q = np.load(BytesIO(io.read_bytes(folder / "robot_q.npy", track=False)))
        host_latency = host.read_probe(folder / "host", tool, loop.Ts)
    score = _score(run, q, documents["predictor"]["outliers"])
    return report(config, built, settings.internal, documents, arrays, host_latency, score,
                  in_process, (load_before, os.getloadavg()))


def _with(role: processes.Role, priority: int) -> processes.Role:
    return dataclasses.replace(role, priority=max(priority, 1))


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
    """Sent, received, lost and late messages of each kind, as the receivers counted them."""
    controller, robot, predictor = (documents[k] for k in ("controller", "robot", "predictor"))
    sent = {"measured_cp": documents["sensor"]["sent"], "forecast_cp": predictor["forecasts"],
            "measured_js": controller["ticks"] + 1, "servo_jf": controller["ticks"]}
    out = {}
    for kind, at in (("measured_cp", controller), ("forecast_cp", controller),
                     ("measured_js", controller)):
        out[kind] = {"sent": sent[kind], **at[kind]}
    arrivals = robot["arrivals"]
    out["servo_jf"] = {"sent": sent["servo_jf"], **{k: arrivals[k]["servo_jf"]
                                                     for k in ("received", "lost", "late")}}
    out["measured_cp_at_predictor"] = {"sent": sent["measured_cp"],
                                       **{k: predictor["arrivals"][k]["measured_cp"]
                                          for k in ("received", "lost", "late")}}
    return out


def report(config: RunConfig, built, internal: bool, documents: dict, arrays: dict,
           host_latency: dict, score: dict, in_process: dict, load: tuple) -> dict:
    """The run's report: timing, packets, the score beside the in-process one."""
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
        "packets": _packets(documents), "bad_datagrams": controller["bad"],
        "stale_encoders": controller["stale_encoders"],
        "torques_missed": robot["torques_missed"], "torques_late": robot["torques_late"],
        "robot_safe_state_ticks": robot["safe_state_ticks"],
        "forecasts_rejected": controller["forecasts_rejected"],
        "forecast_fallback": fallback,
        "points_served_ticks": controller["served"],
        "rms_error_mm": score["rms_error_mm"], "max_error_mm": score["max_error_mm"],
        "scored_samples": score["scored_samples"],
        "in_process_rms_error_mm": in_process["rms_error_mm"],
        "fallbacks": controller["fallbacks"], "failures": controller["failures"],
        "predictor_forecast_ms": documents["predictor"]["forecast_ms"],
        "realtime": {"controller": controller["realtime"], "robot": robot["scheduling"],
                     "sensor": documents["sensor"]["scheduling"],
                     "predictor": documents["predictor"]["scheduling"]},
        "host_load": {"before": [round(v, 2) for v in load[0]],
                      "after": [round(v, 2) for v in load[1]], "cpus": os.cpu_count()},
    }
