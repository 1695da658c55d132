"""The wire format of a deployment, declared once.

Every part of the format is a row of a table here: the header's fields, the kinds of message
(CRTK names) with their row layouts, the authentication code that ends each datagram, the
reasons a receiver drops a datagram, and the keys of the controller program's report. From these
tables :mod:`rhmpc.runtime.wire.codec` builds the Python codec when it is imported, and
:mod:`rhmpc.runtime.wire.generate` writes the C header (``rhmpc/runtime/export/rhmpc_wire.h``)
and the deployment guide's tables; a test fails when a written file differs from what the
tables give.

:data:`VERSION` changes with the layout: :data:`DIGEST` is a hash of every field, kind and the
code's size, and a test fails when the hash of the tables is not the one recorded for the
version.

One datagram is one message::

    header (HEADER, little-endian) | values: rows × width float64 | HMAC-SHA-256 of all before

The code is HMAC (RFC 2104) with SHA-256 (FIPS 180-4) under the run's 32-byte key: only a
process that holds the key makes a message a receiver takes (:mod:`rhmpc.runtime.wire.key`).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

__all__ = ["AUTH", "DIGEST", "DROPS", "HEADER", "KINDS", "MAGIC", "MAX_POINTS", "MAX_ROWS",
           "MAX_STEP", "REPORT", "VERSION", "Field", "Kind", "layout_digest"]

#: The first four bytes of every message.
MAGIC = b"RHMP"
#: The layout's version: raised whenever a field, a kind or the code changes.
VERSION = 2
#: The most tracked points a ``measured_cp`` carries (row 0 the POI).
MAX_POINTS = 64
#: The most rows any message carries (a datagram stays far below 64 KiB).
MAX_ROWS = 1024
#: The largest step forward of a kind's sequence number a receiver takes: a number further
#: ahead (2²⁰ messages, over eight minutes of a 2-kHz stream) is dropped, never adopted, so
#: that no message can lock a stream out.
MAX_STEP = 1 << 20


@dataclass(frozen=True)
class Field:
    """One field of the header: its name, ``struct`` code, C type, unit and meaning."""

    name: str
    code: str
    ctype: str
    unit: str
    doc: str


@dataclass(frozen=True)
class Kind:
    """A kind of message: its number, CRTK name, rows (min, max), width (None: the arm's
    joints), unit, who sends it to whom, and what a row holds."""

    name: str
    number: int
    rows: tuple[int, int]
    width: int | None
    unit: str
    route: str
    doc: str


HEADER: tuple[Field, ...] = (
    Field("magic", "4s", "char[4]", "", "`RHMP`"),
    Field("version", "H", "uint16_t", "", f"the layout's version, {VERSION}"),
    Field("kind", "H", "uint16_t", "", "the kind's number (the kinds' table)"),
    Field("seq", "Q", "uint64_t", "", "the sender's count of its messages of this kind, from 0"),
    Field("stamp", "d", "double", "s", "the instant the values are of"),
    Field("origin", "d", "double", "s",
          "when the sample the values derive from left the sensor (NaN: none)"),
    Field("sent", "d", "double", "s", "when the message was sent"),
    Field("period", "d", "double", "s", "time between rows (`forecast_cp`), else 0"),
    Field("rows", "H", "uint16_t", "", "rows of values"),
    Field("width", "H", "uint16_t", "", "values per row"),
    Field("reserved", "I", "uint32_t", "", "zero (the values start on 8 bytes)"),
)

KINDS: tuple[Kind, ...] = (
    Kind("measured_cp", 1, (1, MAX_POINTS), 3, "m", "sensor → predictor, controller",
         "a tracker's frame: row 0 the POI, rows 1 … the other tracked points, in the "
         "tracker's frame (a row of NaN: not tracked)"),
    Kind("forecast_cp", 2, (4, MAX_ROWS), 3, "m", "predictor → controller",
         "a forecast: row k the POI at stamp + k · period, row 0 the newest sample as the "
         "predictor took it"),
    Kind("measured_js", 3, (1, 1), None, "rad", "robot → controller",
         "the encoders' joint angles of one tick (stamp: that tick's instant)"),
    Kind("servo_jf", 4, (1, 1), None, "N·m", "controller → robot",
         "the joint torques to apply during one tick (stamp: that tick's instant)"),
)

#: The code that ends every datagram: (name, bytes, what it covers).
AUTH = ("HMAC-SHA-256", 32, "every byte before it, under the run's 32-byte key")

#: Why a receiver drops a datagram (counted under each name; none raises).
DROPS: tuple[tuple[str, str], ...] = (
    ("malformed", "not a message of this version: its size, magic, version, kind or shape"),
    ("unauthenticated", "its code is not the one the run's key gives"),
    ("unexpected", "an authenticated kind this receiver does not take"),
    ("late", "a sequence number at or below the last one taken (reordered or replayed)"),
    ("far_ahead", f"a sequence number more than {MAX_STEP} ahead of the last one taken"),
    ("implausible", "values or stamps outside the receiver's bounds"),
)

#: The controller program's report (``PREFIX.json``): (key, what it holds).
REPORT: tuple[tuple[str, str], ...] = (
    ("ticks", "ticks run"),
    ("deadline_misses", "ticks whose torque went out after the next tick began"),
    ("ticks_behind", "ticks begun late, with no sleep before them"),
    ("realtime", "what the host permitted: memory locking, scheduling, pinning"),
    ("stale_encoders", "ticks without a new reading (the observer's hold)"),
    ("late_readings", "readings fused after their own tick (the observer carries them forward)"),
    ("delay_max", "the latest of those [ticks]"),
    ("forecasts_rejected", "forecasts the controller's reference refused"),
    ("send_errors", "torques the socket refused"),
    ("interrupted", "1 when a signal ended the loop"),
    ("stopped", "why the supervisor stopped the run in the safe state (empty: it did not)"),
    ("probe", "1 for the host probe (no controller)"),
    ("received", "messages taken, per kind"),
    ("lost", "messages missing from each kind's sequence"),
    ("dropped", "datagrams dropped, per reason"),
    ("served", "ticks served by each source of points"),
    ("counts", "the reference's and the predictor's events"),
    ("fallbacks", "ticks each fallback of the MPC served"),
    ("failures", "QP results not used, per reason"),
    ("encoder_held", "readings the observer held out"),
    ("tool_error_mm", "the tool against the POI at the measured instants: rms and max [mm]"),
    ("n_s2t", "sensor-to-torque latencies recorded"),
)


def layout_digest() -> str:
    """A hash of the layout (the header's fields, the kinds' numbers and shapes, the code's
    size): 16 hexadecimal digits."""
    h = hashlib.sha256(MAGIC)
    for f in HEADER:
        h.update(f"{f.name}:{f.code};".encode())
    for k in KINDS:
        h.update(f"{k.name}:{k.number}:{k.rows}:{k.width};".encode())
    h.update(f"{AUTH[0]}:{AUTH[1]};{MAX_POINTS};{MAX_ROWS}".encode())
    return h.hexdigest()[:16]


#: The layout's hash for :data:`VERSION`.
DIGEST = "e236cab672712ce0"
