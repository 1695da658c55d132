"""The wire format: round trips, what a receiver refuses, and the sequence numbers' counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rhmpc.runtime.host import histogram_percentiles, percentiles, read_histogram
from rhmpc.runtime.wire import (
    HEADER,
    Arrivals,
    Link,
    Message,
    TrackerClient,
    WireError,
    decode,
    encode,
)


def test_a_message_round_trips_bit_for_bit():
    values = np.random.default_rng(0).normal(size=(5, 3))
    message = Message("forecast_cp", 7, 1.25, values, origin=1.2, sent=1.26, period=0.04)
    data = encode(message)
    assert len(data) == HEADER.size + 8 * 15 == 48 + 120
    back = decode(data)
    assert (back.kind, back.seq, back.stamp, back.origin, back.sent, back.period) == (
        "forecast_cp", 7, 1.25, 1.2, 1.26, 0.04)
    np.testing.assert_array_equal(back.values, values)


def test_the_header_is_laid_out_as_documented():
    data = encode(Message("servo_jf", 0x01020304, 2.0, np.array([[1.0, 2.0, 3.0]])))
    assert data[:4] == b"RHMP" and data[4:6] == b"\x01\x00" and data[6:8] == b"\x04\x00"
    assert data[8:12] == bytes([4, 3, 2, 1])  # little-endian
    assert np.frombuffer(data[12:20], "<f8")[0] == 2.0
    assert data[44:48] == b"\x01\x00\x03\x00"  # 1 row of 3


@pytest.mark.parametrize("mangle", [
    lambda d: d[:40],  # shorter than the header
    lambda d: b"XXXX" + d[4:],  # another format
    lambda d: d[:4] + b"\x02\x00" + d[6:],  # another version
    lambda d: d[:6] + b"\x09\x00" + d[8:],  # an unknown kind
    lambda d: d[:-8],  # values missing
])
def test_a_receiver_refuses_other_datagrams(mangle):
    data = encode(Message("measured_js", 1, 0.5, np.zeros((1, 3))))
    with pytest.raises(WireError):
        decode(mangle(data))


def test_arrivals_count_lost_and_late_messages_and_wrap():
    arrivals = Arrivals()
    seqs = [0, 1, 4, 3, 4, 5, 2**32 - 1]
    taken = [arrivals.take(Message("measured_cp", s, 0.0, np.zeros((1, 3)))) for s in seqs]
    # 4 after 1: 2 lost; 3 and 4 again: late; 2**32 - 1 after 5 is a step back (late)
    assert taken == [0, 0, 2, -1, -1, 0, -1]
    assert arrivals.lost["measured_cp"] == 2 and arrivals.late["measured_cp"] == 3
    wrap = Arrivals()
    for s in (2**32 - 2, 2**32 - 1, 0, 2):
        wrap.take(Message("servo_jf", s, 0.0, np.zeros((1, 3))))
    assert wrap.lost["servo_jf"] == 2**32 - 2 + 1 and wrap.late["servo_jf"] == 0


def test_a_tracker_frame_reaches_every_port_with_one_number():
    a, b = Link(), Link()
    client = TrackerClient([a.port, b.port], epoch_ns=0)
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
