"""The processes beside the controller: the sensor, the predictor and the robot.

Each runs in its own process, started by :mod:`.deployment` with the run it belongs to (built once
by :func:`rhmpc.experiment.assembly.build_run`, so that each holds the very objects of the
in-process simulation), and talks to the others only over UDP in the wire format of
:mod:`.wire`. Time is the run's clock: tick i starts at ``epoch + i·Ts``.

- **sensor** (:func:`sensor`): the samples the in-process loop would give the controller
  (:class:`rhmpc.sim.loop.closed_loop.Refreshes`: a recording's or a scenario's sensor, its rate,
  its latency, its gaps), each sent as ``measured_cp`` on the tick it arrives, to the predictor and
  the controller.
- **predictor** (:func:`predictor`): any predictor of the contract behind the run's reference
  (gate, update, forecast: :meth:`rhmpc.control.reference.PredictedReference.nodes`), a
  ``forecast_cp`` for each sample. A lost sample (a gap in the sequence numbers) is a missing
  one; a late one is dropped.
- **robot** (:func:`robot`): the run's plant stepping in real time: each tick it applies the
  ``servo_jf`` of that tick (the last one if it has not come within 0.7 Ts: counted; after
  :data:`WATCHDOG_TICKS` without one, its drivers' safe state), steps one tick and sends its
  encoders as ``measured_js`` for the next.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from rhmpc import io
from rhmpc.positions import embed3
from rhmpc.runtime.host import percentiles
from rhmpc.runtime.wire import Link, run_clock
from rhmpc.sim.loop.closed_loop import Refreshes, _note_outliers
from rhmpc.tuning.workers import die_with_parent

__all__ = ["BRAKE_S", "ROBOT_WAIT", "WATCHDOG_TICKS", "Ports", "Role", "predictor", "robot",
           "sensor"]

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
    """What a process needs besides its run: the clock, the ports, its folder, its priority."""

    epoch_ns: int
    ticks: int
    Ts: float
    ports: Ports
    folder: Path
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


def _sleep_until(role: Role, tick: float) -> None:
    """Sleep until tick ``tick`` of the run's clock starts (in steps, to hear SIGTERM)."""
    while (left := tick * role.Ts - run_clock(role.epoch_ns)) > 0:
        time.sleep(min(left, 0.1))


def _write(role: Role, name: str, document: dict) -> None:
    io.write_text(role.folder / f"{name}.json", json.dumps(document))


def sensor(run, role: Role, parent: int) -> None:
    """The sensor's samples at their arrival ticks, to the predictor and the controller."""
    stop, scheduling = _start(role, parent)
    loop = run.config.loop
    refreshes = Refreshes(run.stream, loop, run.clock, run.points)
    link = Link(0, role.epoch_ns)
    sent = 0
    while not stop.asked and refreshes.next < role.ticks:
        tick = int(refreshes.next)
        _sleep_until(role, tick)
        for z, stamp, others in refreshes.due(tick):
            rows = [np.full((1, 3), np.nan) if z is None else embed3(z)]
            if others is not None:
                rows.append(embed3(others))
            link.send([role.ports.predictor, role.ports.controller], "measured_cp", stamp,
                      np.vstack(rows), origin=run_clock(role.epoch_ns))
            sent += 1
    link.close()
    _write(role, "sensor", {"sent": sent, "scheduling": scheduling})


def predictor(run, role: Role, parent: int) -> None:
    """The run's predictor behind its reference: a forecast for each sample that arrives."""
    stop, scheduling = _start(role, parent)
    torch = sys.modules.get("torch")  # a learned predictor's: its thread pool is not fork-safe
    if torch is not None:
        torch.set_num_threads(1)  # one thread runs its parallel regions inline
    reference = run.controller.reference
    link = Link(role.ports.predictor, role.epoch_ns)
    log = {"outliers": [], "last_stamp": None}
    dim, made, busy = _dimension(reference), 0, []
    end = role.ticks * role.Ts
    while not stop.asked and run_clock(role.epoch_ns) < end:
        message = link.receive(timeout=0.1)
        if message is None or message.kind != "measured_cp":
            continue
        start = time.perf_counter_ns()
        tick = math.ceil(run_clock(role.epoch_ns) / role.Ts)
        for _ in range(min(link.missed, MAX_FILL)):  # lost samples are missing ones
            reference.nodes(tick, None, message.stamp)
        z = message.values[0, :dim]
        z = None if not np.all(np.isfinite(z)) else z
        others = message.values[1:, :dim] if message.values.shape[0] > 1 else None
        before = reference.predictor.counts["outliers_rejected"], \
            reference.predictor.counts["retracted"]
        nodes = reference.nodes(tick, z, message.stamp, others)
        if z is not None:
            _note_outliers(before, (reference.predictor.counts["outliers_rejected"],
                                    reference.predictor.counts["retracted"]), message.stamp, log)
        if nodes is not None:
            link.send(role.ports.controller, "forecast_cp", nodes[1], embed3(nodes[0]),
                      origin=message.origin, period=reference.dt)
            made += 1
        busy.append(time.perf_counter_ns() - start)
    link.close()
    _write(role, "predictor", {"forecasts": made, "outliers": log["outliers"],
                               "scheduling": scheduling, "arrivals": link.arrivals.counts(),
                               "forecast_ms": percentiles(np.array(busy) * 1e-6)})


def _dimension(reference) -> int:
    """The coordinates the predictor reads (1 or 3)."""
    dim = getattr(getattr(reference.predictor, "settings", None), "dim", None)
    return 3 if dim is None else int(dim)


class _Drivers:
    """What a robot's drivers do with the torques: apply each tick's, hold the last one through
    a short silence, and past :data:`WATCHDOG_TICKS` without one enter their safe state, gravity
    compensation with viscous braking from the encoders, τ = ĝ(q) − M(q) q̇ / BRAKE_S (clipped
    to the torque limits), until torques come again."""

    def __init__(self, robot, Ts: float) -> None:
        self.robot, self.Ts, self.data = robot, Ts, robot.create_data()
        self.tau, self.silent, self.missed, self.safe = np.zeros(robot.nv), 0, 0, 0
        self.last: np.ndarray | None = None

    def torque(self, command: np.ndarray | None, reading: np.ndarray) -> np.ndarray:
        speed = np.zeros_like(reading) if self.last is None else (reading - self.last) / self.Ts
        self.last = reading
        if command is not None:
            self.tau, self.silent = np.asarray(command, dtype=float), 0
            return self.tau
        self.missed += 1
        self.silent += 1
        if self.silent <= WATCHDOG_TICKS:
            return self.tau  # the last torque holds
        self.safe += 1
        gravity = pin.computeGeneralizedGravity(self.robot.model, self.data, reading)
        brake = gravity - self.robot.mass_matrix(reading) @ speed / BRAKE_S
        limit = self.robot.torque_limit
        return np.clip(brake, -limit, limit)


def robot(run, role: Role, parent: int) -> None:
    """The run's plant in the robot's place: one tick per tick of the run's clock, behind its
    drivers (:class:`_Drivers`)."""
    stop, scheduling = _start(role, parent)
    plant, Ts = run.plant, role.Ts
    link = Link(role.ports.robot, role.epoch_ns)
    q = np.full((role.ticks, plant.q.size), np.nan)
    drivers, late, reading = _Drivers(run.robot, Ts), 0, plant.encoders()
    link.send(role.ports.controller, "measured_js", 0.0, reading)
    for i in range(role.ticks):
        if stop.asked:
            break
        command, sent = None, run_clock(role.epoch_ns)
        while command is None:  # until 0.7 Ts into the tick, and 0.2 Ts after the reading
            left = max((i + ROBOT_WAIT) * Ts, sent + ROBOT_ANSWER * Ts) - run_clock(role.epoch_ns)
            message = link.receive(timeout=max(left, 0.0))
            if message is None:
                break
            tick = round(message.stamp / Ts)
            if message.kind == "servo_jf" and tick == i:
                command = message.values[0]
            elif message.kind == "servo_jf" and tick < i:
                late += 1  # a torque for a tick already stepped: stale
        plant.step(drivers.torque(command, reading))
        q[i] = plant.q
        reading = plant.encoders()
        link.send(role.ports.controller, "measured_js", (i + 1) * Ts, reading)
    link.close()
    with io.atomic_write(role.folder / "robot_q.npy") as out:
        np.save(out, q)
    _write(role, "robot", {"torques_missed": drivers.missed, "torques_late": late,
                           "safe_state_ticks": drivers.safe, "scheduling": scheduling,
                           "arrivals": link.arrivals.counts()})
