"""The host-stall meter, on a scripted clock."""

import numpy as np
import pytest

from rhmpc.timing.host import host_stalls, stall_summary


def scripted_clock(steps_ns):
    """A clock that advances by the given steps, then by 1 µs forever."""
    now, steps = [0], iter(steps_ns)

    def clock() -> int:
        now[0] += next(steps, 1_000)
        return now[0]

    return clock


def test_host_stalls_returns_every_gap_at_or_above_the_floor():
    steps = [1_000] * 5 + [20_000, 5_000, 150_000, 19_999, 1_000, 300_000]
    gaps = host_stalls(0.001, clock=scripted_clock(steps))
    np.testing.assert_array_equal(gaps, [20_000, 150_000, 300_000])


def test_host_stalls_of_a_host_that_never_stalls_is_empty():
    assert host_stalls(0.002, clock=scripted_clock([])).size == 0


def test_stall_summary_in_microseconds_and_gain_ticks():
    doc = stall_summary(np.array([20_000, 150_000, 300_000]), 1.0, gain_us=2.0)
    assert doc == {"seconds": 1.0, "floor_us": 20.0, "stalls": 3, "longest_us": 300.0,
                   "longest_g": 150.0, "over_g": 50.0, "over_50_g": 2}
    assert stall_summary(np.array([150_000]), 1.0, gain_us=2.0, over_g=80.0)["over_80_g"] == 0
    assert stall_summary(np.array([], dtype=np.int64), 0.5) == {
        "seconds": 0.5, "floor_us": 20.0, "stalls": 0, "longest_us": 0.0}


@pytest.mark.parametrize("seconds", [-1.0, float("nan"), float("inf")])
def test_host_stalls_rejects_a_bad_duration(seconds):
    with pytest.raises(ValueError, match="seconds"):
        host_stalls(seconds)
