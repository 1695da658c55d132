"""The wire format between the processes of a deployment, version 1, and a Python client.

Each message is one UDP datagram: a 48-byte header, then ``rows × width`` values, all
little-endian (``rhmpc/runtime/export/rhmpc_wire.h`` is the same format in C)::

    offset  type     field
    0       4 bytes  magic   b"RHMP"
    4       uint16   version 1
    6       uint16   kind    1 measured_cp, 2 forecast_cp, 3 measured_js, 4 servo_jf
    8       uint32   seq     the sender's count of messages of this kind, from 0 (wraps)
    12      float64  stamp   the instant the values are of [s], on the run's clock
    20      float64  origin  when the sample the values derive from left the sensor [s]
    28      float64  sent    when this message was sent [s]
    36      float64  period  time between rows [s] (forecast_cp), else 0
    44      uint16   rows
    46      uint16   width
    48      float64  values[rows * width], row after row

The run's clock is ``CLOCK_MONOTONIC`` less the run's epoch: every process of a run reads the
same clock (one host). The kinds carry CRTK names (the dVRK's robot interfaces): ``measured_cp``
a tracker's sample, row 0 the POI and rows 1 … the other tracked points (NaN: not measured), in
metres in the tracker's frame (the controller is placed with the tracker's point that sits at its
origin, ``--center``); ``measured_js`` the encoders' joint
angles [rad] of one tick (its stamp is that tick's instant); ``servo_jf`` the joint torques
[N·m] computed from them (the same stamp). ``forecast_cp`` (CRTK has no name for it) is a
predictor's forecast: row k the POI at ``stamp + k · period``, row 0 the newest sample as the
predictor took it.

A receiver counts each kind's sequence numbers (:class:`Arrivals`): a gap is that many lost
messages, a number at or below the last one taken is a late (reordered or duplicated) message,
which is dropped. A datagram that is not of this format or version is counted as bad and
dropped.
"""

from __future__ import annotations

import math
import socket
import struct
import time
from dataclasses import dataclass

import numpy as np

__all__ = ["HEADER", "KINDS", "MAGIC", "VERSION", "Arrivals", "Link", "Message", "TrackerClient",
           "WireError", "decode", "encode", "run_clock"]

MAGIC, VERSION = b"RHMP", 1
HEADER = struct.Struct("<4sHHIddddHH")
KINDS = {"measured_cp": 1, "forecast_cp": 2, "measured_js": 3, "servo_jf": 4}
_NAMES = {v: k for k, v in KINDS.items()}
#: The most values a message carries (a datagram stays below 64 KiB).
MAX_VALUES = 4096


class WireError(ValueError):
    """A datagram that is not a message of this format and version."""


@dataclass(frozen=True)
class Message:
    """One message: its kind (a CRTK name), sequence number, instants [s] and values."""

    kind: str
    seq: int
    stamp: float
    values: np.ndarray
    origin: float = math.nan
    sent: float = math.nan
    period: float = 0.0


def encode(message: Message) -> bytes:
    """The datagram of ``message`` (values as a (rows, width) array of floats)."""
    values = np.ascontiguousarray(np.atleast_2d(message.values), dtype="<f8")
    rows, width = values.shape
    if values.size > MAX_VALUES:
        raise WireError(f"{values.size} values: at most {MAX_VALUES} fit a message")
    head = HEADER.pack(MAGIC, VERSION, KINDS[message.kind], message.seq & 0xFFFFFFFF,
                       message.stamp, message.origin, message.sent, message.period, rows, width)
    return head + values.tobytes()


def decode(data: bytes) -> Message:
    """The message of a datagram; :class:`WireError` for one of another format or version."""
    if len(data) < HEADER.size:
        raise WireError(f"{len(data)} bytes: shorter than the {HEADER.size}-byte header")
    magic, version, kind, seq, stamp, origin, sent, period, rows, width = HEADER.unpack_from(data)
    if magic != MAGIC or version != VERSION or kind not in _NAMES:
        raise WireError(f"not a version-{VERSION} message (magic {magic!r}, version {version}, "
                        f"kind {kind})")
    if len(data) != HEADER.size + 8 * rows * width:
        raise WireError(f"{len(data)} bytes for {rows} x {width} values")
    values = np.frombuffer(data, dtype="<f8", offset=HEADER.size).reshape(rows, width)
    return Message(_NAMES[kind], seq, stamp, values.astype(float), origin, sent, period)


def run_clock(epoch_ns: int) -> float:
    """Now on the run's clock: ``CLOCK_MONOTONIC`` less ``epoch_ns``, in seconds."""
    return (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - epoch_ns) * 1e-9


class Arrivals:
    """Sequence numbers of the messages of each kind taken so far: lost and late ones counted.

    :meth:`take` returns how many messages of the kind were lost just before this one (a
    gap in the numbers), or −1 for a late one (at or below the last number taken: reordered or
    duplicated; drop it). Numbers wrap at 2³²: a step forward is taken modulo 2³².
    """

    def __init__(self) -> None:
        self.last: dict[str, int] = {}
        self.received = {k: 0 for k in KINDS}
        self.lost = {k: 0 for k in KINDS}
        self.late = {k: 0 for k in KINDS}
        self.bad = 0

    def take(self, message: Message) -> int:
        kind = message.kind
        self.received[kind] += 1
        last = self.last.get(kind)
        step = 1 if last is None else (message.seq - last) & 0xFFFFFFFF
        if last is not None and (step == 0 or step > 0x7FFFFFFF):
            self.late[kind] += 1
            return -1
        missed = message.seq if last is None else step - 1
        self.lost[kind] += missed
        self.last[kind] = message.seq
        return missed

    def counts(self) -> dict:
        """received, lost and late per kind, and the bad datagrams."""
        return {"received": dict(self.received), "lost": dict(self.lost),
                "late": dict(self.late), "bad": self.bad}


class Link:
    """A UDP endpoint on one port: sends numbered messages to peers, receives any.

    Parameters
    ----------
    port : int
        The local port (0: any free one; :attr:`port` tells which).
    epoch_ns : int
        The run's epoch on ``CLOCK_MONOTONIC`` [ns]: the ``sent`` stamps are on the run's clock.
    host : str
        The address to bind and to send to (loopback by default).
    """

    def __init__(self, port: int = 0, epoch_ns: int = 0, host: str = "127.0.0.1") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.host, self.port, self.epoch_ns = host, self.sock.getsockname()[1], epoch_ns
        self.seq = {k: 0 for k in KINDS}
        self.arrivals = Arrivals()
        self.missed = 0  # messages of its kind lost just before the last one received

    def send(self, ports: int | list[int], kind: str, stamp: float, values,
             origin: float = math.nan, period: float = 0.0) -> None:
        """Send ``values`` (rows, width) of ``kind`` stamped ``stamp`` [s] to ``ports`` (one
        message, one sequence number)."""
        message = Message(kind, self.seq[kind], stamp, np.asarray(values, dtype=float), origin,
                          run_clock(self.epoch_ns), period)
        self.seq[kind] += 1
        data = encode(message)
        for port in [ports] if isinstance(ports, int) else ports:
            self.sock.sendto(data, (self.host, port))

    def receive(self, timeout: float | None) -> Message | None:
        """The next message in order (late ones counted and skipped), or None when ``timeout``
        [s] passes without one (None: wait; 0: only what has arrived)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(65536)
            except (TimeoutError, BlockingIOError):
                return None
            try:
                message = decode(data)
            except WireError:
                self.arrivals.bad += 1
                continue
            missed = self.arrivals.take(message)
            if missed >= 0:
                self.missed = missed
                return message

    def close(self) -> None:
        self.sock.close()


class TrackerClient:
    """A tracker's side: each frame's POI (and the other tracked points) to the predictor and
    the controller, as ``measured_cp``.

    >>> client = TrackerClient([9001, 9002], epoch_ns)         # doctest: +SKIP
    >>> client.send(stamp, poi, others)      # stamp: the frame's instant on the run's clock [s]
    """

    def __init__(self, ports: list[int], epoch_ns: int, host: str = "127.0.0.1") -> None:
        self.link, self.ports = Link(0, epoch_ns, host), list(ports)

    def send(self, stamp: float, poi, others=None) -> None:
        """One frame: ``poi`` (3,) [m] (NaN: not tracked), ``others`` (n, 3) [m] or None."""
        rows = np.atleast_2d(np.asarray(poi, dtype=float))
        if others is not None:
            rows = np.vstack([rows, np.asarray(others, dtype=float).reshape(-1, 3)])
        self.link.send(self.ports, "measured_cp", stamp, rows,
                       origin=run_clock(self.link.epoch_ns))

    def close(self) -> None:
        self.link.close()
