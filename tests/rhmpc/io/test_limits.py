"""Bounds from one table: a count that does not fit is refused, naming the largest that does."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rhmpc import io
from rhmpc.io.limits import MEMORY_BUDGET, TIME_BUDGET, Bound


def test_every_bound_states_its_measurement() -> None:
    for name, bound in io.BOUNDS.items():
        assert bound.source and bound.what, name
        assert bound.largest() >= 1


def test_the_largest_value_fits_and_the_next_does_not() -> None:
    bound = Bound("things", bytes_each=1000.0, seconds_each=1.0)
    top = bound.largest(memory_scale=2.0, time_scale=3.0, workers=2)
    assert top == math.floor(min(MEMORY_BUDGET / 2000.0, 2 * TIME_BUDGET / 3.0))
    bound.check(top, "--n", 2.0, 3.0, 2)
    with pytest.raises(ValueError, match=rf"^--n: {top + 1} things would take .*; at most "
                                         rf"{top} fit in 2 GiB of memory and a day of "
                                         "computing on 2 workers$"):
        bound.check(top + 1, "--n", 2.0, 3.0, 2)


@settings(max_examples=50, deadline=None, derandomize=True)
@given(value=st.integers(1, 10**15), name=st.sampled_from(sorted(io.BOUNDS)))
def test_a_check_passes_exactly_up_to_the_largest(value: int, name: str) -> None:
    top = io.largest(name)
    try:
        io.check(name, value, "--x")
    except ValueError as exc:
        assert value > top and str(exc).startswith("--x: ") and "\n" not in str(exc)
    else:
        assert value <= top
