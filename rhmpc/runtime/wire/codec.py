"""The Python codec of the wire format, built from its tables (:mod:`.table`) at import.

:func:`seal` makes the datagram of a message under a key; :func:`unseal` checks a datagram's
size and code before it reads a field of it, and raises :class:`Dropped` with the reason
(one of :data:`~.table.DROPS`) for one it does not take.
"""

from __future__ import annotations

import hmac
import math
import struct
from dataclasses import dataclass

import numpy as np

from rhmpc.runtime.wire.table import AUTH, HEADER, KINDS, MAGIC, MAX_ROWS, VERSION

__all__ = ["HEAD", "MAC_BYTES", "NAMES", "NUMBERS", "OFFSETS", "Dropped", "Message", "seal",
           "unseal"]

#: The header as a ``struct``, little-endian, in the table's order.
HEAD = struct.Struct("<" + "".join(f.code for f in HEADER))
#: Where each field of the header starts [bytes].
OFFSETS = {f.name: struct.calcsize("<" + "".join(g.code for g in HEADER[:i]))
           for i, f in enumerate(HEADER)}
#: Bytes of the code that ends a datagram.
MAC_BYTES = AUTH[1]
NUMBERS = {k.name: k.number for k in KINDS}
NAMES = {k.number: k for k in KINDS}


class Dropped(ValueError):
    """A datagram a receiver does not take; ``reason`` is one of the table's drops."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


@dataclass(frozen=True)
class Message:
    """One message: its kind (a CRTK name), sequence number, instants [s] and values (rows,
    width)."""

    kind: str
    seq: int
    stamp: float
    values: np.ndarray
    origin: float = math.nan
    sent: float = math.nan
    period: float = 0.0


def _code(key: bytes, data: bytes) -> bytes:
    """HMAC-SHA-256 of ``data`` under ``key``."""
    return hmac.digest(key, data, "sha256")


def seal(message: Message, key: bytes) -> bytes:
    """The datagram of ``message`` under ``key``: header, values, code."""
    values = np.ascontiguousarray(np.atleast_2d(message.values), dtype="<f8")
    rows, width = values.shape
    if not (1 <= rows <= MAX_ROWS and 1 <= width <= 0xFFFF):
        raise ValueError(f"{rows} x {width} values: a message holds 1 … {MAX_ROWS} rows")
    head = HEAD.pack(MAGIC, VERSION, NUMBERS[message.kind], message.seq, message.stamp,
                     message.origin, message.sent, message.period, rows, width, 0)
    body = head + values.tobytes()
    return body + _code(key, body)


def unseal(data: bytes, key: bytes, joints: int | None = None) -> Message:
    """The message of a datagram: its size from its header, its code under ``key``, then its
    fields and shape (``joints``: the width of the joint-space kinds; None: any).
    :class:`Dropped` for one that fails any of these."""
    if len(data) < HEAD.size + MAC_BYTES:
        raise Dropped("malformed", f"{len(data)} bytes")
    rows, width = struct.unpack_from("<HH", data, OFFSETS["rows"])
    if len(data) != HEAD.size + 8 * rows * width + MAC_BYTES:
        raise Dropped("malformed", f"{len(data)} bytes for {rows} x {width} values")
    body = memoryview(data)[:-MAC_BYTES]
    if not hmac.compare_digest(_code(key, body), data[-MAC_BYTES:]):
        raise Dropped("unauthenticated")
    magic, version, number, seq, stamp, origin, sent, period, _, _, _ = HEAD.unpack_from(data)
    kind = NAMES.get(number)
    if magic != MAGIC or version != VERSION or kind is None:
        raise Dropped("malformed", f"magic {magic!r}, version {version}, kind {number}")
    if not (kind.rows[0] <= rows <= kind.rows[1]) or (kind.width or joints or width) != width:
        raise Dropped("malformed", f"{kind.name} of {rows} x {width} values")
    values = np.frombuffer(data, dtype="<f8", count=rows * width, offset=HEAD.size)
    return Message(kind.name, seq, stamp, values.reshape(rows, width).astype(float), origin,
                   sent, period)
