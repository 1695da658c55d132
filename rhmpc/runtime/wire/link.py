"""A process's end of the wire: a UDP socket that seals what it sends and checks what it takes.

:class:`Receiver` is the receiving rule, the same in every receiver (the C programs follow it
too): a datagram is authenticated before any of its fields is read, then its kind, its bounds
(:class:`~rhmpc.runtime.wire.bounds.Bounds`) and its sequence number are judged. Whatever fails
is counted under its reason (:data:`~rhmpc.runtime.wire.table.DROPS`) and dropped; nothing
raises. A sequence number at or below the last one taken is late (reordered or replayed), one
more than :data:`~rhmpc.runtime.wire.table.MAX_STEP` ahead is dropped, never adopted: no
message can lock a stream out.
"""

from __future__ import annotations

import math
import socket
import time
from collections.abc import Callable, Iterable

import numpy as np

from rhmpc.runtime.wire.bounds import Bounds
from rhmpc.runtime.wire.codec import Dropped, Message, seal, unseal
from rhmpc.runtime.wire.table import DROPS, KINDS, MAX_STEP

__all__ = ["Link", "Receiver", "TrackerClient", "bind", "run_clock"]


def run_clock(epoch_ns: int) -> float:
    """Now on the run's clock: ``CLOCK_MONOTONIC`` less ``epoch_ns``, in seconds."""
    return (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - epoch_ns) * 1e-9


#: The receive buffer a socket asks for [bytes]: a burst of foreign datagrams between two
#: drains must not push out the run's own (the host caps it at ``net.core.rmem_max``).
RECEIVE_BUFFER = 1 << 20


def bind(port: int = 0, host: str = "127.0.0.1") -> socket.socket:
    """A UDP socket bound to ``port`` (0: any free one), with a receive buffer of
    :data:`RECEIVE_BUFFER` where the host allows it. :class:`OSError` names the port."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
        try:  # beyond rmem_max where permitted (CAP_NET_ADMIN), else up to it
            sock.setsockopt(socket.SOL_SOCKET, option, RECEIVE_BUFFER)
            break
        except (OSError, TypeError):
            continue
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise OSError(exc.errno, f"UDP port {port} on {host}: {exc.strerror}") from None
    return sock


class Receiver:
    """The receiving rule: authenticate, decode, bound, order; count every drop.

    Parameters
    ----------
    key : bytes
        The run's key.
    accepts : iterable of str
        The kinds this receiver takes.
    bounds : Bounds or None
        The plausibility bounds (None: only finiteness of the stamps is not checked either;
        for tests of the codec alone).
    clock : callable
        Now on the run's clock [s].
    """

    def __init__(self, key: bytes, accepts: Iterable[str], bounds: Bounds | None,
                 clock: Callable[[], float]) -> None:
        self.key, self.accepts, self.bounds, self.clock = key, set(accepts), bounds, clock
        self.last: dict[str, int] = {}
        self.received = {k.name: 0 for k in KINDS}
        self.lost = {k.name: 0 for k in KINDS}
        self.dropped = {reason: 0 for reason, _ in DROPS}
        self.missed = 0  # messages of its kind lost just before the last one taken

    def take(self, data: bytes) -> Message | None:
        """The message of ``data`` if it is taken, else None (counted)."""
        try:
            message = unseal(data, self.key, None if self.bounds is None else self.bounds.joints)
        except Dropped as drop:
            self.dropped[drop.reason] += 1
            return None
        if message.kind not in self.accepts:
            return self._drop("unexpected")
        if self.bounds is not None and self.bounds.problem(message, self.clock()) is not None:
            return self._drop("implausible")
        last = self.last.get(message.kind)
        if last is not None and message.seq <= last:
            return self._drop("late")
        if message.seq - (-1 if last is None else last) > MAX_STEP:
            return self._drop("far_ahead")
        self.missed = message.seq - (-1 if last is None else last) - 1
        self.last[message.kind] = message.seq
        self.received[message.kind] += 1
        self.lost[message.kind] += self.missed
        return message

    def _drop(self, reason: str) -> None:
        self.dropped[reason] += 1
        return None

    def counts(self) -> dict:
        """received and lost per kind, dropped per reason."""
        return {"received": dict(self.received), "lost": dict(self.lost),
                "dropped": dict(self.dropped)}


class Link:
    """A UDP endpoint: sends sealed, numbered messages to peers and takes checked ones.

    Parameters
    ----------
    sock : socket.socket
        A bound UDP socket (:func:`bind`; a deployment binds every port before it starts its
        processes, which inherit them).
    key : bytes
        The run's key.
    epoch_ns : int
        The run's epoch on ``CLOCK_MONOTONIC`` [ns].
    accepts : iterable of str
        The kinds this end takes (none: it only sends).
    bounds : Bounds or None
        What it takes as plausible.
    host : str
        The address it sends to.
    """

    def __init__(self, sock: socket.socket, key: bytes, epoch_ns: int,
                 accepts: Iterable[str] = (), bounds: Bounds | None = None,
                 host: str = "127.0.0.1") -> None:
        self.sock, self.key, self.epoch_ns, self.host = sock, key, epoch_ns, host
        self.port = sock.getsockname()[1]
        self.seq = {k.name: 0 for k in KINDS}
        self.receiver = Receiver(key, accepts, bounds, self.now)

    def now(self) -> float:
        """Now on the run's clock [s]."""
        return run_clock(self.epoch_ns)

    def send(self, ports: int | list[int], kind: str, stamp: float, values,
             origin: float = math.nan, period: float = 0.0) -> None:
        """Send ``values`` (rows, width) of ``kind`` stamped ``stamp`` [s] to ``ports``: one
        message, one sequence number."""
        data = seal(Message(kind, self.seq[kind], stamp, np.asarray(values, dtype=float),
                            origin, self.now(), period), self.key)
        self.seq[kind] += 1
        for port in [ports] if isinstance(ports, int) else ports:
            try:
                self.sock.sendto(data, (self.host, port))
            except OSError:
                pass  # a peer that is gone: the receivers count what is missing

    def receive(self, timeout: float | None) -> Message | None:
        """The next message taken, or None when ``timeout`` [s] passes without one (None:
        wait; 0: only what has arrived). Dropped datagrams are counted and skipped."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            self.sock.settimeout(left)
            try:
                data = self.sock.recv(65536)
            except (TimeoutError, BlockingIOError):
                return None
            message = self.receiver.take(data)
            if message is not None:
                return message

    @property
    def missed(self) -> int:
        """Messages of its kind lost just before the last one taken."""
        return self.receiver.missed

    def close(self) -> None:
        self.sock.close()


class TrackerClient:
    """A tracker's side: each frame's POI (and the other tracked points) to the predictor and
    the controller, as ``measured_cp``, sealed with the run's key.

    >>> key = read_key("run.key")                              # doctest: +SKIP
    >>> client = TrackerClient([9001, 9002], key, epoch_ns)     # doctest: +SKIP
    >>> client.send(stamp, poi, others)     # stamp: the frame's instant on the run's clock [s]
    """

    def __init__(self, ports: list[int], key: bytes, epoch_ns: int,
                 host: str = "127.0.0.1") -> None:
        self.link, self.ports = Link(bind(0, host), key, epoch_ns, host=host), list(ports)

    def send(self, stamp: float, poi, others=None) -> None:
        """One frame: ``poi`` (3,) [m] (NaN: not tracked), ``others`` (n, 3) [m] or None."""
        rows = np.atleast_2d(np.asarray(poi, dtype=float))
        if others is not None:
            rows = np.vstack([rows, np.asarray(others, dtype=float).reshape(-1, 3)])
        self.link.send(self.ports, "measured_cp", stamp, rows, origin=self.link.now())

    def close(self) -> None:
        self.link.close()
