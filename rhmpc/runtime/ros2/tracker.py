"""The tracker's side over ROS 2: samples from a topic into the run, forecasts and status out.

The tracker bridge takes the sensor process's place in a deployment (``rhmpc sil --tracker
ros2:TOPIC``). It subscribes to ``TOPIC`` with the type its publisher announces,
``geometry_msgs/PoseStamped`` (the POI) or ``geometry_msgs/PoseArray`` (every tracked point,
the POI the run's ``--poi``-th, from 1), and sends each sample, sealed under the run's key, as
``measured_cp`` to the predictor and the controller: what the wire's receivers take from the
sensor. It publishes each of the predictor's forecasts as ``nav_msgs/Path`` on
``/rhmpc/forecast_cp`` and the run's status (:mod:`rhmpc.runtime.ros2.status`).

**Stamps.** A sample is of its header's instant, ROS time mapped onto the run's clock
(:class:`~rhmpc.runtime.ros2.names.RosClock`); a header left at zero is of its arrival. The
bridge sends a sample only when its instant lies within the receivers' window
(``Bounds.max_age`` before now to ``Bounds.ahead`` after it), after the last one sent, and at or
after the run's instant 0, and its points within the receivers' bounds: it counts every other
sample under its reason and drops it, as the receivers would. A gap of more than one of the
run's sample periods between two stamps is first sent as the missing samples (rows of NaN, at
most :attr:`~rhmpc.sim.loop.closed_loop.Refreshes.MAX_FILL`), as the sensor process does.

A Path's poses are the forecast's points in the samples' frame (their ``frame_id``), pose k at
``stamp + k · period`` in ROS time; the Path's own stamp is the forecast's first instant.

This module imports ``cyclonedds`` (the ``ros2`` extra): :mod:`rhmpc.runtime.deployment`
imports it only for a run with ``--tracker``.
"""

from __future__ import annotations

import json
import threading
from io import BytesIO

import numpy as np

from rhmpc import io
from rhmpc.runtime import processes
from rhmpc.runtime.ros2.dds import Node
from rhmpc.runtime.ros2.messages import (
    Header,
    Path,
    PoseArray,
    PoseStamped,
    message_name,
    nanoseconds,
    point_of,
    pose_at,
    time_of,
)
from rhmpc.runtime.ros2.names import NAMESPACE, RosClock
from rhmpc.runtime.ros2.status import Status
from rhmpc.runtime.wire import Link, Message, bind
from rhmpc.sim.loop.closed_loop import Refreshes

__all__ = ["FORECAST_TOPIC", "SAMPLE_TYPES", "Samples", "forecast_path", "taken", "tracker"]

#: Where the forecasts are published.
FORECAST_TOPIC = f"{NAMESPACE}/forecast_cp"
#: The message types a tracker's topic may carry.
SAMPLE_TYPES = {message_name(t): t for t in (PoseStamped, PoseArray)}
#: Why the bridge drops a sample.
SAMPLE_DROPS = ("stamp", "order", "before_start", "no_poi", "implausible")


class Samples:
    """The samples of the tracker's topic, checked, stamped on the run's clock and sent.

    Parameters
    ----------
    link : Link
        Where the samples leave from (its own socket: the bridge's receive thread sends).
    role : processes.Role
        The run's clock, ports, bounds.
    clock : RosClock
        ROS time against the run's clock.
    dt : float
        The run's sample period [s] (a gap's missing samples).
    poi : int
        The POI's index in a PoseArray (from 0).
    others : bool
        Whether the run's predictor reads the other tracked points.
    """

    def __init__(self, link: Link, role: processes.Role, clock: RosClock, dt: float, poi: int,
                 others: bool) -> None:
        self.link, self.role, self.clock, self.dt = link, role, clock, dt
        self.poi, self.others = poi, others
        self.sent, self.taken, self.last = 0, [], None
        self.frame, self.received = "", 0
        self.dropped = dict.fromkeys(SAMPLE_DROPS, 0)
        self.lock = threading.Lock()

    def take(self, sample) -> None:
        """One sample of the topic (PoseStamped or PoseArray)."""
        with self.lock:
            self.received += 1
            reason = self._send(sample)
            if reason is not None:
                self.dropped[reason] += 1

    def _rows(self, sample) -> np.ndarray | None:
        """Row 0 the POI, then (where the predictor reads them) the other points; a point not
        finite is a row of NaN (not tracked). None: no POI in the sample."""
        if isinstance(sample, PoseStamped):
            return point_of(sample.pose)[None, :]
        if len(sample.poses) <= self.poi:
            return None
        points = [point_of(p) for p in sample.poses]
        order = [self.poi] + ([i for i in range(len(points)) if i != self.poi][:63]
                              if self.others else [])
        rows = np.array([points[i] for i in order])
        rows[~np.isfinite(rows).all(axis=1)] = np.nan
        return rows

    def _send(self, sample) -> str | None:
        now = self.clock.now()
        ns = nanoseconds(sample.header.stamp)
        t = now if ns == 0 else self.clock.run_time(ns)
        bounds = self.role.bounds
        if not now - bounds.max_age <= t <= now + bounds.ahead:
            return "stamp"
        if t < 0:
            return "before_start"
        if self.last is not None and t <= self.last:
            return "order"
        rows = self._rows(sample)
        if rows is None:
            return "no_poi"
        if bounds.problem(Message("measured_cp", 0, t, rows, sent=now), now) is not None:
            return "implausible"
        self._fill(t)
        self.link.send([self.role.ports.predictor, self.role.ports.controller], "measured_cp",
                       t, rows, origin=self.link.now())
        self.sent, self.last, self.frame = self.sent + 1, t, sample.header.frame_id
        self.taken.append((t, *rows[0]))
        return None

    def _fill(self, t: float) -> None:
        """A gap's missing samples, as rows of NaN stamped ``t`` (the sensor process's rule)."""
        if self.last is None:
            return
        missing = min(max(round((t - self.last) / self.dt) - 1, 0), Refreshes.MAX_FILL)
        for _ in range(missing):
            self.link.send([self.role.ports.predictor, self.role.ports.controller],
                           "measured_cp", t, np.full((1, 3), np.nan), origin=self.link.now())
            self.sent += 1

    def counts(self) -> dict:
        return {"received": self.received, "sent": self.sent, "dropped": dict(self.dropped)}


def forecast_path(message: Message, clock: RosClock, frame: str) -> Path:
    """The forecast ``message`` as a Path: pose k at ``stamp + k · period`` in ROS time."""
    epoch = clock.epoch_ros_ns()
    stamps = [epoch + round((message.stamp + k * message.period) * 1e9)
              for k in range(len(message.values))]
    return Path(Header(time_of(stamps[0]), frame),
                [PoseStamped(Header(time_of(ns), frame), pose_at(row))
                 for ns, row in zip(stamps, message.values, strict=True)])


def _subscribe(node: Node, topic: str, samples: Samples) -> str | None:
    """Subscribe to ``topic`` with its publisher's type once one is discovered; the type's
    name, or None while no publisher of a type the bridge reads is known."""
    for name in sorted(node.published_types(topic)):
        if name in SAMPLE_TYPES:
            if SAMPLE_TYPES[name] is PoseStamped and samples.others:
                raise ValueError(f"{topic} carries {name}, the POI alone, and the run's "
                                 "predictor reads the other tracked points: publish them all "
                                 "as a PoseArray, or choose a predictor of the POI alone")
            node.subscription(topic, SAMPLE_TYPES[name], samples.take)
            return name
    return None


def tracker(run, role: processes.Role, sock, topic: str, parent: int) -> None:
    """The tracker bridge's process: samples of ``topic`` in, forecasts and status out, until
    the run's end."""
    stop, scheduling = processes.set_up(role, parent)
    clock = RosClock(role.epoch_ns)
    forecasts = Link(sock, role.key, role.epoch_ns, accepts=("forecast_cp",), bounds=role.bounds)
    poi = int(run.config.data_read.get("point", 1)) - 1 if run.config.data else 0
    others = run.points is not None and getattr(run.controller.reference.predictor,
                                                "multi_point", False)
    samples = Samples(Link(bind(0), role.key, role.epoch_ns), role, clock, run.clock.dt, poi,
                      others)
    node = Node()
    path_writer, status = node.publisher(FORECAST_TOPIC, Path), Status(
        node, "tracker bridge", clock, role.ticks * role.Ts)
    kind, published, end = None, 0, role.ticks * role.Ts
    while not stop.asked and clock.now() < end:
        kind = kind or _subscribe(node, topic, samples)
        message = forecasts.receive(timeout=0.05)
        if message is not None:
            path_writer.write(forecast_path(message, clock, samples.frame))
            published += 1
        status.update(_values(samples, kind, published), _warning(samples, kind, clock, role))
    values = _values(samples, kind, published)
    status.end(stop.asked and clock.now() < end, values)
    with samples.lock:
        taken = np.array(samples.taken, dtype=float).reshape(-1, 4)
        document = {"sent": samples.sent, "scheduling": scheduling, "ros2": {
            "topic": topic, "type": kind, "frame_id": samples.frame, **samples.counts(),
            "malformed": sum(d.malformed for d in node.listeners),
            "forecasts_published": published, "forecasts": forecasts.receiver.counts()}}
    io.write_bytes(role.folder / "samples.npy", _npy(taken))
    io.write_text(role.folder / "sensor.json", json.dumps(document))


def _values(samples: Samples, kind: str | None, published: int) -> dict:
    counts = samples.counts()
    return {"samples_type": kind or "none yet", "samples_received": counts["received"],
            "samples_sent": counts["sent"],
            **{f"samples_dropped_{k}": v for k, v in counts["dropped"].items() if v},
            "forecasts_published": published}


def _warning(samples: Samples, kind: str | None, clock: RosClock, role) -> str | None:
    """Why the run's samples do not flow, or None."""
    if kind is None:
        return "no publisher of PoseStamped or PoseArray on the samples' topic"
    last = samples.last
    silent = clock.now() - (0.0 if last is None else last)
    if silent > role.bounds.max_age:
        return f"no sample taken for {silent:.1f} s"
    return None


def taken(folder, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The samples the bridge of a run in ``folder`` sent, (instants [s], POI (n, ``dim``)
    [m]): where the tracker measured the POI. ValueError, on one line, when it sent none."""
    array = np.load(BytesIO(io.read_bytes(folder / "samples.npy", track=False)))
    if not len(array):
        ros2 = io.read_json(folder / "sensor.json", track=False)["ros2"]
        why = "no publisher of PoseStamped or PoseArray was found" if ros2["type"] is None \
            else f"of {ros2['received']} received, dropped: {ros2['dropped']}"
        raise ValueError(f"the tracker bridge sent no sample of {ros2['topic']} ({why}); "
                         "the run's score has nothing to compare with")
    return array[:, 0], array[:, 1:1 + dim]


def _npy(array: np.ndarray) -> bytes:
    """``array`` in NumPy's ``.npy`` format."""
    buffer = BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()

