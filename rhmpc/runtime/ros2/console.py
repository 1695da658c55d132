"""The robot's side over ROS 2: a dVRK-style console's arm in the simulator's place.

The console bridge takes the robot process's place in a deployment (``rhmpc sil --console
ros2:NAMESPACE --allow-unauthenticated``). Between it and the controller runs the wire: it
takes the controller's ``servo_jf`` (authenticated, bounded) and sends the arm's readings as
``measured_js`` sealed under the run's key. Between it and the arm run the CRTK topics of the
dVRK, ``sensor_msgs/JointState`` under the arm's namespace:

- ``NAMESPACE/servo_jf`` (published): the efforts of the actuated joints, by their names in the
  robot file [N·m], stamped with the tick they are for (its instant in ROS time). A torque
  whose tick has passed when it comes is not published (counted late).
- ``NAMESPACE/measured_js`` (subscribed): the positions of those joints, found by name (or in
  order when the message names none), stamped with the instant of the reading. A reading is of
  the tick nearest its stamp on the run's clock (:class:`~rhmpc.runtime.ros2.names.RosClock`;
  a stamp left at zero is of the next tick to begin) and is sent while that tick is at most
  the observer's ``max_delay`` old (the controller fuses a late reading into its own tick and
  carries it forward), after the last one sent, and within the receivers' bounds (joint
  limits, stamps); every other reading is counted under its reason.

ROS 2 without SROS2 authenticates nothing: any process on the DDS domain can publish readings
here and read the torques, which is why a deployment refuses this bridge without
``allow_unauthenticated``. The console's drivers keep their own limits and watchdog: the
bridge publishes no torque for a tick the controller missed, and cannot brake the arm itself
(the wire's robot-side template, ``robot_client.c``, shows the watchdog the drivers need).

This module imports ``cyclonedds`` (the ``ros2`` extra).
"""

from __future__ import annotations

import json
import math
import threading
from io import BytesIO

import numpy as np

from rhmpc import io
from rhmpc.runtime import processes
from rhmpc.runtime.ros2.dds import Node
from rhmpc.runtime.ros2.messages import Header, JointState, nanoseconds, time_of
from rhmpc.runtime.ros2.names import RosClock
from rhmpc.runtime.ros2.status import Status
from rhmpc.runtime.wire import Link, Message, bind

__all__ = ["READING_DROPS", "Readings", "console", "joint_names"]

#: Why the bridge drops a reading.
READING_DROPS = ("joints", "before_start", "passed", "order", "implausible")


def joint_names(robot) -> list[str]:
    """The actuated joints' names, in the order of the controller's joint vector."""
    model = robot.model
    joints = [j for j in range(1, model.njoints) if model.joints[j].nv > 0]
    return [model.names[j] for j in sorted(joints, key=lambda j: model.joints[j].idx_v)]


class Readings:
    """The arm's readings from ``measured_js``, each checked, put on a tick and sent.

    Parameters
    ----------
    link : Link
        Where the readings leave from (its own socket: the bridge's receive thread sends).
    role : processes.Role
        The run's clock, ports, bounds.
    clock : RosClock
        ROS time against the run's clock.
    names : list of str
        The actuated joints.
    late : int
        The most ticks a reading may come after its own and still be sent (the controller's
        observer's ``delay_ticks``).
    """

    def __init__(self, link: Link, role: processes.Role, clock: RosClock,
                 names: list[str], late: int) -> None:
        self.link, self.role, self.clock, self.names = link, role, clock, names
        self.late = late
        self.q = np.full((role.ticks, len(names)), np.nan)  # after tick i: the reading of i + 1
        self.received, self.sent, self.last = 0, 0, -1
        self.dropped = dict.fromkeys(READING_DROPS, 0)
        self.lock = threading.Lock()

    def take(self, reading: JointState) -> None:
        """One message of ``measured_js``."""
        with self.lock:
            self.received += 1
            reason = self._send(reading)
            if reason is not None:
                self.dropped[reason] += 1

    def _positions(self, reading: JointState) -> np.ndarray | None:
        if reading.name:
            if not set(self.names) <= set(reading.name) or \
                    len(reading.position) != len(reading.name):
                return None
            return np.array([reading.position[reading.name.index(n)] for n in self.names])
        return np.array(reading.position) if len(reading.position) == len(self.names) else None

    def _send(self, reading: JointState) -> str | None:
        q = self._positions(reading)
        if q is None:
            return "joints"
        Ts, now, ns = self.role.Ts, self.clock.now(), nanoseconds(reading.header.stamp)
        tick = math.ceil(now / Ts) if ns == 0 else round(self.clock.run_time(ns) / Ts)
        if tick < 0:
            return "before_start"
        if tick < math.floor(now / Ts) - self.late:
            return "passed"
        if tick <= self.last:
            return "order"
        if self.role.bounds.problem(Message("measured_js", 0, tick * Ts, q[None, :], sent=now),
                                    now) is not None:
            return "implausible"
        self.link.send(self.role.ports.controller, "measured_js", tick * Ts, q[None, :])
        self.sent, self.last = self.sent + 1, tick
        if 1 <= tick <= self.role.ticks:
            self.q[tick - 1] = q
        return None

    def counts(self) -> dict:
        return {"received": self.received, "sent": self.sent, "dropped": dict(self.dropped)}


def console(run, role: processes.Role, sock, namespace: str, parent: int) -> None:
    """The console bridge's process: torques out to ``NAMESPACE/servo_jf``, readings in from
    ``NAMESPACE/measured_js``, until the run's end."""
    stop, scheduling = processes.set_up(role, parent)
    clock, Ts, end = RosClock(role.epoch_ns), role.Ts, role.ticks * role.Ts
    torques = Link(sock, role.key, role.epoch_ns, accepts=("servo_jf",), bounds=role.bounds)
    names = joint_names(run.robot)
    readings = Readings(Link(bind(0), role.key, role.epoch_ns), role, clock, names,
                        run.controller.observer.delay_ticks)
    node = Node()
    writer = node.publisher(f"{namespace}/servo_jf", JointState)
    node.subscription(f"{namespace}/measured_js", JointState, readings.take)
    status = Status(node, "console bridge", clock, end)
    published, late = 0, 0
    while not stop.asked and clock.now() < end:
        message = torques.receive(timeout=0.05)
        if message is not None:
            tick = round(message.stamp / Ts)
            if tick < math.floor(clock.now() / Ts):
                late += 1
            else:
                writer.write(JointState(Header(time_of(clock.ros_time(tick * Ts))), names,
                                        effort=[float(v) for v in message.values[0]]))
                published += 1
        status.update(_values(readings, published, late), _warning(readings, clock, role))
    status.end(stop.asked and clock.now() < end, _values(readings, published, late))
    _write(role, readings, torques, {"torques_missed": max(role.ticks - published - late, 0),
                                     "torques_late": late, "ticks_behind": 0,
                                     "safe_state_ticks": None, "scheduling": scheduling},
           {"namespace": namespace, "joints": names, "torques_published": published,
            "malformed": sum(d.malformed for d in node.listeners)})


def _values(readings: Readings, published: int, late: int) -> dict:
    counts = readings.counts()
    return {"torques_published": published, "torques_late": late,
            "readings_received": counts["received"], "readings_sent": counts["sent"],
            **{f"readings_dropped_{k}": v for k, v in counts["dropped"].items() if v}}


def _warning(readings: Readings, clock: RosClock, role: processes.Role) -> str | None:
    """Why the arm's readings do not serve, or None."""
    behind = clock.now() / role.Ts - readings.last
    if behind > processes.WATCHDOG_TICKS:
        return f"no reading sent for {behind * role.Ts * 1e3:.0f} ms"
    return None


def _write(role: processes.Role, readings: Readings, torques: Link, document: dict,
           ros2: dict) -> None:
    """The robot's documents, as the simulator writes them: its report and the readings."""
    with readings.lock:
        buffer = BytesIO()
        np.save(buffer, readings.q)
        document |= {"arrivals": torques.receiver.counts(),
                     "ros2": ros2 | {"readings": readings.counts()}}
    io.write_bytes(role.folder / "robot_q.npy", buffer.getvalue())
    io.write_text(role.folder / "robot.json", json.dumps(document))
