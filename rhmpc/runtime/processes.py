"""The processes beside the controller: the sensor, the predictor and the robot.

Each runs in its own process, forked by :mod:`.deployment` from the run it belongs to (built
once by :func:`rhmpc.experiment.assembly.build_run`, so that each holds the very objects of the
in-process simulation), with its socket already bound and the run's key in memory. It talks to
the others only over UDP in the wire format of :mod:`.wire`: every message it sends is sealed,
every one it takes authenticated and bounded first (:class:`~rhmpc.runtime.wire.Receiver`).
Time is the run's clock: tick i starts at ``epoch + i·Ts``.

- **sensor** (:func:`sensor`): the samples the in-process loop would give the controller
  (:class:`rhmpc.sim.loop.closed_loop.Refreshes`), each sent as ``measured_cp`` on the tick it
  arrives, to the predictor and the controller.
- **predictor** (:func:`predictor`): any predictor of the contract behind the run's reference
  (gate, update, forecast: :meth:`rhmpc.control.reference.PredictedReference.nodes`), a
  ``forecast_cp`` for each sample. A lost sample (a gap in the sequence numbers) is a missing
  one.
- **robot** (:func:`robot`): the run's plant stepping in real time behind its drivers
  (:class:`Drivers`): each tick it applies the ``servo_jf`` of that very tick, steps and sends
  its encoders as ``measured_js`` for the next. Behind the clock (a busy host), it steps the
  ticks already past at once, each with the torque meant for it, and sends no stale reading.

A process that fails writes its cause on one line to ``ROLE.fault`` in the run's folder and
exits 1; the deployment names it.
"""

from __future__ import annotations

import ctypes
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path

import numpy as np
import pinocchio as pin

from rhmpc import io
from rhmpc.control.reference import embed3
from rhmpc.runtime.host import percentiles
from rhmpc.runtime.wire import Bounds, Link
from rhmpc.sim.loop.closed_loop import Refreshes, _note_outliers
from rhmpc.tuning.workers import die_with_parent

__all__ = ["BRAKE_S", "ROBOT_WAIT", "WATCHDOG_TICKS", "Drivers", "Ports", "Role", "predictor",
           "robot", "sensor"]

#: How long into a tick the robot waits for that tick's torque [ticks], and at least how long
#: after sending its reading (a robot that fell behind still gives the controller time to answer).
ROBOT_WAIT, ROBOT_ANSWER = 0.7, 0.2
#: Ticks without a torque after which the drivers leave the last one for their safe state (10 ms:
#: the last torque, 0.2 N·m on the PHANToM's 4 g·m², moves its tool by under a millimetre).
WATCHDOG_TICKS = 20
#: The safe state's braking time constant [s]: the joint speeds decay e-fold in it.
BRAKE_S = 0.02
#: The most missing samples a gap in the sequence numbers fills (as the loop's fills).
MAX_FILL = Refreshes.MAX_FILL


@dataclass(frozen=True)
class Ports:
    """The UDP ports on loopback of the controller, the predictor and the robot."""

    controller: int
    predictor: int
    robot: int


@dataclass(frozen=True)
class Role:
    """What a process needs besides its run: the clock, the ports, the key, the bounds, its
    folder, its priority."""

    epoch_ns: int
    ticks: int
    Ts: float
    ports: Ports
    folder: Path
    key: bytes
    bounds: Bounds
    priority: int = 0  # SCHED_FIFO priority where permitted; 0: the default scheduler
    controller_cpu: int | None = None  # the controller's processor, which this one leaves


class _Stop:
    """SIGTERM asks the process to stop; Ctrl-C is the deployment's to handle."""

    def __init__(self) -> None:
        self.asked = False
        signal.signal(signal.SIGTERM, self._ask)
        signal.signal(signal.SIGINT, signal.SIG_IGN)

    def _ask(self, *_) -> None:
        self.asked = True


def _start(role: Role, parent: int) -> tuple[_Stop, str]:
    """The process's set-up: it dies with the deployment; SCHED_FIFO where asked and permitted."""
    die_with_parent(parent)
    stop = _Stop()
    others = os.sched_getaffinity(0) - {role.controller_cpu}
    if role.controller_cpu is not None and others:
        os.sched_setaffinity(0, others)  # the controller's processor is the controller's
    if role.priority <= 0:
        return stop, "SCHED_OTHER"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(role.priority))
        return stop, f"SCHED_FIFO priority {role.priority}"
    except (OSError, AttributeError) as exc:
        return stop, f"SCHED_OTHER (SCHED_FIFO not permitted: {exc})"


def run_part(name: str, body: Callable[..., None], *args) -> None:
    """Run a process's ``body`` under the name ``rhmpc-NAME`` (as ``ps`` and ``top`` show it);
    a failure is one line in ``NAME.fault`` and exit status 1 (the deployment names the part
    and the cause)."""
    role = args[1]
    _name_process(f"rhmpc-{name}")
    try:
        body(*args)
    except BaseException as exc:
        text = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
        io.write_text(role.folder / f"{name}.fault", text + "\n")
        sys.stderr.flush()
        os._exit(1)


def _name_process(name: str) -> None:
    """The process's name in ``/proc/PID/comm`` (Linux ``prctl(PR_SET_NAME)``, 15 bytes)."""
    try:
        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)
    except (OSError, AttributeError):
        pass


def _sleep_until(role: Role, tick: float, stop: _Stop) -> None:
    """Sleep until tick ``tick`` of the run's clock starts (in steps, to hear SIGTERM)."""
    while not stop.asked and (left := tick * role.Ts - run_clock(role)) > 0:
        time.sleep(min(left, 0.1))


def run_clock(role: Role) -> float:
    return (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - role.epoch_ns) * 1e-9


def _write(role: Role, name: str, document: dict) -> None:
    io.write_text(role.folder / f"{name}.json", json.dumps(document))


def sensor(run, role: Role, sock, parent: int) -> None:
    """The sensor's samples at their arrival ticks, to the predictor and the controller."""
    stop, scheduling = _start(role, parent)
    refreshes = Refreshes(run.stream, run.config.loop, run.clock, run.points)
    link = Link(sock, role.key, role.epoch_ns)
    sent = 0
    while not stop.asked and refreshes.next < role.ticks:
        tick = int(refreshes.next)
        _sleep_until(role, tick, stop)
        for z, stamp, others in refreshes.due(tick):
            rows = [np.full((1, 3), np.nan) if z is None else embed3(z)]
            if others is not None:
                rows.append(embed3(others))
            link.send([role.ports.predictor, role.ports.controller], "measured_cp", stamp,
                      np.vstack(rows), origin=link.now())
            sent += 1
    link.close()
    _write(role, "sensor", {"sent": sent, "scheduling": scheduling})


def predictor(run, role: Role, sock, parent: int) -> None:
    """The run's predictor behind its reference: a forecast for each sample taken."""
    stop, scheduling = _start(role, parent)
    torch = sys.modules.get("torch")  # a learned predictor's: its thread pool is not fork-safe
    if torch is not None:
        torch.set_num_threads(1)  # one thread runs its parallel regions inline
    reference = run.controller.reference
    link = Link(sock, role.key, role.epoch_ns, accepts=("measured_cp",), bounds=role.bounds)
    log = {"outliers": [], "last_stamp": None}
    dim, made, busy = _dimension(reference), 0, []
    while not stop.asked and link.now() < role.ticks * role.Ts:
        message = link.receive(timeout=0.1)
        if message is None:
            continue
        start = time.perf_counter_ns()
        if _forecast(reference, link, message, dim, log, role):
            made += 1
        busy.append(time.perf_counter_ns() - start)
    link.close()
    _write(role, "predictor", {"forecasts": made, "outliers": log["outliers"],
                               "scheduling": scheduling, "arrivals": link.receiver.counts(),
                               "forecast_ms": percentiles(np.array(busy) * 1e-6)})


def _forecast(reference, link: Link, message, dim: int, log: dict, role: Role) -> bool:
    """One sample through the reference (a gap's missing samples first); its forecast sent to
    the controller. Returns whether one was sent."""
    tick = math.ceil(link.now() / role.Ts)
    for _ in range(min(link.missed, MAX_FILL)):  # lost samples are missing ones
        reference.nodes(tick, None, message.stamp)
    z = message.values[0, :dim]
    z = None if not np.all(np.isfinite(z)) else z
    others = message.values[1:, :dim] if message.values.shape[0] > 1 else None
    counts = reference.predictor.counts
    before = counts["outliers_rejected"], counts["retracted"]
    nodes = reference.nodes(tick, z, message.stamp, others)
    if z is not None:
        _note_outliers(before, (counts["outliers_rejected"], counts["retracted"]),
                       message.stamp, log)
    if nodes is None:
        return False
    link.send(role.ports.controller, "forecast_cp", nodes[1], embed3(nodes[0]),
              origin=message.origin, period=reference.dt)
    return True


def _dimension(reference) -> int:
    """The coordinates the predictor reads (1 or 3)."""
    dim = getattr(getattr(reference.predictor, "settings", None), "dim", None)
    return 3 if dim is None else int(dim)


class Drivers:
    """What a robot's drivers do with the torques: apply each tick's, hold the last one through
    a short silence, and past :data:`WATCHDOG_TICKS` without one enter their safe state, gravity
    compensation with viscous braking from the encoders, τ = ĝ(q) − M(q) q̇ / BRAKE_S (clipped
    to the torque limits), until torques come again. They hold the arm so until the first
    torque (those ticks are not counted as missed)."""

    def __init__(self, robot, Ts: float) -> None:
        self.robot, self.Ts, self.data = robot, Ts, robot.create_data()
        self.tau, self.silent, self.missed, self.safe = np.zeros(robot.nv), WATCHDOG_TICKS, 0, 0
        self.last: np.ndarray | None = None
        self.started = False

    def torque(self, command: np.ndarray | None, reading: np.ndarray) -> np.ndarray:
        speed = np.zeros_like(reading) if self.last is None else (reading - self.last) / self.Ts
        self.last = reading
        if command is not None:
            self.tau, self.silent, self.started = np.asarray(command, dtype=float), 0, True
            return self.tau
        self.missed += self.started
        self.silent += 1
        if self.silent <= WATCHDOG_TICKS:
            return self.tau  # the last torque holds
        self.safe += self.started
        gravity = pin.computeGeneralizedGravity(self.robot.model, self.data, reading)
        brake = gravity - self.robot.mass_matrix(reading) @ speed / BRAKE_S
        limit = self.robot.torque_limit
        return np.clip(brake, -limit, limit)


def _this_ticks_torque(link: Link, i: int, Ts: float, sent: float, pending: dict,
                       counts: dict):
    """The ``servo_jf`` stamped with tick ``i``, awaited until ROBOT_WAIT into the tick (and
    ROBOT_ANSWER after the reading went out), or None. One for a tick already past is late
    (counted, dropped); one for a tick to come waits in ``pending`` for its tick (a robot that
    fell behind the clock catches up with the torques meant for each tick)."""
    if i in pending:
        return pending.pop(i)
    while True:
        left = max((i + ROBOT_WAIT) * Ts, sent + ROBOT_ANSWER * Ts) - link.now()
        message = link.receive(timeout=max(left, 0.0))
        if message is None:
            return None
        tick = round(message.stamp / Ts)
        if tick == i:
            return message.values[0]
        if tick < i:
            counts["late"] += 1
        else:
            pending[tick] = message.values[0]
            for old in [t for t in pending if t < i]:
                del pending[old]


def robot(run, role: Role, sock, parent: int) -> None:
    """The run's plant in the robot's place: one tick per tick of the run's clock, behind its
    drivers (:class:`Drivers`)."""
    stop, scheduling = _start(role, parent)
    plant, Ts = run.plant, role.Ts
    link = Link(sock, role.key, role.epoch_ns, accepts=("servo_jf",), bounds=role.bounds)
    q = np.full((role.ticks, plant.q.size), np.nan)
    drivers, counts, reading = Drivers(run.robot, Ts), {"late": 0, "behind": 0}, plant.encoders()
    pending: dict[int, np.ndarray] = {}
    _sleep_until(role, -0.5, stop)  # the reading of tick 0, there as tick 0 begins
    link.send(role.ports.controller, "measured_js", 0.0, reading)
    for i in range(role.ticks):
        if stop.asked:
            break
        command = _this_ticks_torque(link, i, Ts, link.now(), pending, counts)
        plant.step(drivers.torque(command, reading))
        q[i] = plant.q
        reading = plant.encoders()
        if link.now() < (i + 2) * Ts:  # else behind the clock: catch up, no stale reading
            link.send(role.ports.controller, "measured_js", (i + 1) * Ts, reading)
        else:
            counts["behind"] += 1
    link.close()
    buffer = BytesIO()
    np.save(buffer, q)
    io.write_bytes(role.folder / "robot_q.npy", buffer.getvalue())
    _write(role, "robot", {"torques_missed": drivers.missed, "torques_late": counts["late"],
                           "ticks_behind": counts["behind"], "safe_state_ticks": drivers.safe,
                           "scheduling": scheduling, "arrivals": link.receiver.counts()})
