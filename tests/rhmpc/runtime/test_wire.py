"""The wire format: its one table, the sealed round trip, the key file, and what a receiver
takes: authenticated, expected, plausible, in order; everything else counted, nothing raised."""

from __future__ import annotations

import hashlib
import hmac
import math
import os
import struct

import numpy as np
import pytest

from rhmpc.runtime.host import histogram_percentiles, percentiles, read_histogram
from rhmpc.runtime.wire import (
    MAX_STEP,
    Bounds,
    Dropped,
    KeyFileError,
    Link,
    Message,
    Receiver,
    TrackerClient,
    bind,
    new_key,
    read_key,
    seal,
    unseal,
)
from rhmpc.runtime.wire.codec import HEAD, OFFSETS
from rhmpc.runtime.wire.table import DIGEST, HEADER, KINDS, VERSION, layout_digest

KEY = bytes(range(32))
BOUNDS = Bounds(torque_max=(1.0, 1.0, 1.0), joint_lower=(-1.0, -1.0, -1.0),
                joint_upper=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.05), radius=0.05)


def test_the_layout_and_its_version_change_together():
    """The layout's hash is the one recorded for this version: a change to a field, a kind or
    the code without a new version (and a new hash) fails here."""
    assert layout_digest() == DIGEST, (
        f"the wire's layout changed (hash {layout_digest()}): raise VERSION ({VERSION}) in "
        "rhmpc/runtime/wire/table.py, record the new hash in DIGEST and regenerate "
        "(python -m rhmpc.runtime.wire.generate)")
    assert HEAD.size % 8 == 0 and [f.name for f in HEADER][:4] == ["magic", "version", "kind",
                                                                     "seq"]


def test_a_sealed_message_round_trips_bit_for_bit():
    values = np.random.default_rng(0).normal(size=(5, 3))
    message = Message("forecast_cp", 7, 1.25, values, origin=1.2, sent=1.26, period=0.04)
    data = seal(message, KEY)
    assert len(data) == HEAD.size + 8 * 15 + 32
    back = unseal(data, KEY)
    assert (back.kind, back.seq, back.stamp, back.origin, back.sent, back.period) == (
        "forecast_cp", 7, 1.25, 1.2, 1.26, 0.04)
    np.testing.assert_array_equal(back.values, values)


def test_the_code_is_rfc_2104_hmac_sha256_of_everything_before_it():
    """An independent HMAC (RFC 2104 written out over hashlib's SHA-256) gives the code."""
    data = seal(Message("servo_jf", 3, 2.0, np.array([[1.0, 2.0, 3.0]])), KEY)
    body, code = data[:-32], data[-32:]
    key = KEY.ljust(64, b"\0")
    inner = hashlib.sha256(bytes(k ^ 0x36 for k in key) + body).digest()
    assert code == hashlib.sha256(bytes(k ^ 0x5C for k in key) + inner).digest()
    assert data[:4] == b"RHMP" and struct.unpack_from("<H", data, OFFSETS["version"])[0] == 2
    assert struct.unpack_from("<Q", data, OFFSETS["seq"])[0] == 3


@pytest.mark.parametrize("mangle, reason", [
    (lambda d: d[:40], "malformed"),                         # shorter than a header and a code
    (lambda d: d[:-8], "malformed"),                         # a value missing
    (lambda d: d[:20] + bytes([d[20] ^ 1]) + d[21:], "unauthenticated"),  # one bit flipped
    (lambda d: d[:-1] + bytes([d[-1] ^ 1]), "unauthenticated"),           # the code's last bit
    (lambda d: _resealed(b"XXXX" + d[4:-32]), "malformed"),  # another format, correctly sealed
    (lambda d: _resealed(d[:6] + b"\x09\x00" + d[8:-32]), "malformed"),   # an unknown kind
])
def test_a_receiver_names_why_it_drops_a_datagram(mangle, reason):
    data = seal(Message("measured_js", 1, 0.5, np.zeros((1, 3))), KEY)
    with pytest.raises(Dropped) as drop:
        unseal(mangle(data), KEY)
    assert drop.value.reason == reason


def _resealed(body: bytes) -> bytes:
    return body + hmac.digest(KEY, body, "sha256")


def test_another_key_does_not_authenticate():
    data = seal(Message("servo_jf", 0, 0.0, np.zeros((1, 3))), new_key())
    with pytest.raises(Dropped, match="unauthenticated"):
        unseal(data, KEY)


def _taking(accepts=("servo_jf",), now=0.0):
    return Receiver(KEY, accepts, BOUNDS, lambda: now)


def test_sequence_numbers_count_losses_and_no_number_locks_a_stream_out():
    """Gaps are losses; a number at or below the last is late; one beyond MAX_STEP is dropped,
    never adopted: the messages that follow in order are still taken."""
    receiver = _taking()
    seqs = [0, 1, 4, 3, 4, 5, 5 + MAX_STEP + 1, 2**63, 6, 7]
    taken = [receiver.take(seal(Message("servo_jf", s, 0.0, np.zeros((1, 3)), sent=0.0), KEY))
             is not None for s in seqs]
    assert taken == [True, True, True, False, False, True, False, False, True, True]
    assert receiver.lost["servo_jf"] == 2 and receiver.received["servo_jf"] == 6
    assert receiver.dropped["late"] == 2 and receiver.dropped["far_ahead"] == 2
    first = _taking()  # a first number far ahead is not adopted either
    assert first.take(seal(Message("servo_jf", MAX_STEP + 5, 0.0, np.zeros((1, 3)), sent=0.0),
                           KEY)) is None
    assert first.take(seal(Message("servo_jf", 0, 0.0, np.zeros((1, 3)), sent=0.0), KEY))


@pytest.mark.parametrize("kind, values, extra, problem", [
    ("servo_jf", [[np.nan, 0, 0]], {}, "torques"),
    ("servo_jf", [[1e300, 0, 0]], {}, "torques"),
    ("servo_jf", [[1.5, 0, 0]], {}, "torques"),                    # beyond the torque limit
    ("servo_jf", [[0.5, 0, 0]], {"stamp": 1000.0}, "stamp"),       # from the future
    ("servo_jf", [[0.5, 0, 0]], {"stamp": -10.0}, "stamp"),        # stale
    ("servo_jf", [[0.5, 0, 0]], {"sent": 5.0}, "sent"),            # sent in the future
    ("measured_js", [[0.0, 3.0, 0.0]], {}, "joint"),               # beyond the limits + margin
    ("measured_cp", [[0.0, 0.0, 1.05]], {}, "registration"),       # a metre off
    ("measured_cp", [[0.0, 0.0, 0.05], [np.nan, 0.0, 0.0]], {}, "partly"),
    ("measured_cp", [[0.0, 0.0, 0.05], [0.0, 0.0, 1e300]], {}, "registration"),  # another point
    ("forecast_cp", [[0.0, 0.0, 0.05]] * 4, {"period": 0.0}, "period"),
    ("forecast_cp", [[0.0, 0.0, 1e308]] * 4, {"period": 0.04}, "registration"),
])
def test_bounds_name_an_implausible_message(kind, values, extra, problem):
    message = Message(kind, 0, extra.get("stamp", 0.0), np.array(values, dtype=float),
                      sent=extra.get("sent", 0.0), period=extra.get("period", 0.0))
    assert problem in BOUNDS.problem(message, now=0.0)
    receiver = _taking((kind,))
    assert receiver.take(seal(message, KEY)) is None and receiver.dropped["implausible"] == 1


def test_plausible_messages_pass_the_bounds():
    ok = [Message("servo_jf", 0, 0.0, np.array([[1.0, -1.0, 0.0]]), sent=0.0),
          Message("measured_js", 0, 0.0005, np.array([[1.05, -1.05, 0.0]]), sent=0.0),
          Message("measured_cp", 0, -0.1, np.array([[0.0, 0.01, 0.06], [np.nan] * 3,
                                                    [0.2, 0.0, 0.05]]), sent=0.0),
          Message("forecast_cp", 0, -0.1, np.tile([0.0, 0.0, 0.08], (4, 1)), sent=0.0,
                  period=0.04)]
    assert [BOUNDS.problem(m, now=0.0) for m in ok] == [None] * 4


def test_a_receiver_drops_kinds_it_does_not_take():
    receiver = _taking(("measured_cp",))
    data = seal(Message("servo_jf", 0, 0.0, np.zeros((1, 3)), sent=0.0), KEY)
    assert receiver.take(data) is None and receiver.dropped["unexpected"] == 1


def test_a_key_file_must_be_the_users_own_and_private(tmp_path):
    key = new_key()
    path = tmp_path / "run.key"
    path.write_text(key.hex() + "\n")
    path.chmod(0o600)
    assert read_key(path) == key
    path.chmod(0o640)
    with pytest.raises(KeyFileError, match="read by others"):
        read_key(path)
    path.chmod(0o600)
    link = tmp_path / "link.key"
    link.symlink_to(path)
    with pytest.raises(KeyFileError, match="cannot open"):
        read_key(link)  # not through a link
    for bad in ("abc", "zz" * 32, key.hex() * 2):
        path.write_text(bad)
        with pytest.raises(KeyFileError, match="64 hexadecimal digits"):
            read_key(path)


def test_a_key_reaches_a_process_through_an_inherited_pipe():
    read, write = os.pipe()
    key = new_key()
    os.write(write, key.hex().encode() + b"\n")
    os.close(write)
    assert read_key(f"/dev/fd/{read}") == key
    with pytest.raises(OSError):
        os.fstat(read)  # read once, then closed


def test_a_tracker_frame_reaches_every_port_with_one_number():
    epoch = 0
    a = Link(bind(), KEY, epoch, accepts=("measured_cp",))
    b = Link(bind(), KEY, epoch, accepts=("measured_cp",))
    client = TrackerClient([a.port, b.port], KEY, epoch_ns=epoch)
    try:
        client.send(0.5, [1e-3, 2e-3, 3e-3], others=[[0.0, 0.0, 0.0], [np.nan] * 3])
        client.send(0.54, [np.nan] * 3)
        for link in (a, b):
            first, second = link.receive(timeout=5.0), link.receive(timeout=5.0)
            assert (first.seq, second.seq) == (0, 1) and first.values.shape == (3, 3)
            np.testing.assert_array_equal(first.values[0], [1e-3, 2e-3, 3e-3])
            assert np.isnan(second.values).all() and math.isfinite(first.origin)
        assert a.receive(timeout=0.0) is None
    finally:
        for link in (a, b, client):
            link.close()


def test_a_flood_of_foreign_datagrams_is_counted_and_the_real_ones_taken():
    """Random bytes, the documented header under no key, and sealed messages under another
    key, between two real ones: both real ones are taken in order, the rest counted."""
    rng = np.random.default_rng(5)
    link = Link(bind(), KEY, 0, accepts=("servo_jf",))
    foreign = bind()
    real = Link(bind(), KEY, 0)
    other = new_key()
    try:
        real.send(link.port, "servo_jf", 0.0, [[0.1, 0.2, 0.3]])
        for i in range(90):  # within a socket's default buffer
            body = HEAD.pack(b"RHMP", VERSION, 4, 2**40 + i, 0.0, 0.0, 0.0, 0.0, 1, 3, 0)
            junk = (rng.bytes(int(rng.integers(1, 600))), body + np.zeros(3).tobytes() +
                    rng.bytes(32), seal(Message("servo_jf", 2**40 + i, 0.0,
                                                np.full((1, 3), 50.0)), other))
            foreign.sendto(junk[i % 3], ("127.0.0.1", link.port))
        real.send(link.port, "servo_jf", 0.0, [[0.4, 0.5, 0.6]])
        got = [link.receive(timeout=5.0) for _ in range(2)]
        assert [m.seq for m in got] == [0, 1]
        np.testing.assert_array_equal(got[1].values, [[0.4, 0.5, 0.6]])
        dropped = link.receiver.dropped
        assert dropped["malformed"] + dropped["unauthenticated"] == 90
        assert dropped["unauthenticated"] == 60
    finally:
        for end in (link, real):
            end.close()
        foreign.close()


def test_the_generated_files_are_the_tables():
    """The committed C header and the guide's tables are what the tables give today."""
    from importlib.resources import files
    from pathlib import Path

    from rhmpc.runtime.wire.generate import GUIDE_MARKS, c_header, guide_tables

    header = files("rhmpc.runtime").joinpath("export", "rhmpc_wire.h").read_text()
    assert header == c_header(), "python -m rhmpc.runtime.wire.generate"
    assert "Generated by rhmpc.runtime.wire.generate" in header.splitlines()[2]
    guide = (Path(__file__).resolve().parents[3] / "docs" / "guide" / "your-robot.md").read_text()
    begin, end = guide.index(GUIDE_MARKS[0]), guide.index(GUIDE_MARKS[1]) + len(GUIDE_MARKS[1])
    assert guide[begin:end] == guide_tables(), "python -m rhmpc.runtime.wire.generate"


def test_every_kind_of_the_table_has_a_bounds_rule():
    for kind in KINDS:
        assert hasattr(Bounds, f"_{kind.name}")


def test_cyclictest_histograms_and_latencies_give_percentiles():
    text = ("# Histogram\n000020 000050\n000021 000030\n000100 000019\n# Total: 000000100\n"
            "# Min Latencies: 00020\n# Avg Latencies: 00031\n# Max Latencies: 12977\n"
            "# Histogram Overflows: 00001\n# Histogram Overflow at cycle number:\n"
            "# Thread 0: 00042\n")
    values, weights, top = read_histogram(text)
    assert histogram_percentiles(values, weights, top) == {"p50": 20.0, "p99": 100.0,
                                                           "max": 12977.0}
    assert weights[values >= 100].sum() == 20  # the bin of 100 µs and the overflow
    assert percentiles(np.arange(1, 101)) == {"p50": 50.5, "p99": 99.0, "max": 100.0}
    assert percentiles([])["p99"] is None
