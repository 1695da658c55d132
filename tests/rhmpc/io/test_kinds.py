"""A settings table's values against its dataclass's annotations: the kind only."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from rhmpc.io import check_kinds
from rhmpc.io.kinds import fits


@dataclass(frozen=True)
class Example:
    duration: float = 1.0
    ticks: int = 1
    name: str = "a"
    flag: bool = False
    settling: float | None = None
    gate: float | str = 1.0
    blocks: tuple[int, ...] | None = None
    band: tuple[float, float] = (0.5, 3.0)
    table: dict = None
    anything: Any = None


#: (value, annotation, whether it fits)
CASES = [
    (1.5, float, True), (2, float, True), (np.float64(1.5), float, True),
    (np.int64(2), int, True), (2.0, int, True),  # whether it is whole, the class says
    (True, float, False), (np.True_, int, False), ("1.5", float, False), ({}, float, False),
    ([1.0], float, False), ("x", str, True), (1, str, False), (True, bool, True),
    (1, bool, False), (None, float | None, True), (None, float, False),
    ("tuna", float | str, True),
    ({"a": 1}, float | str, False), ([1, 2], tuple[int, ...], True),
    (np.array([1.0, 2.0]), tuple[float, float], True), ([1, True], tuple[int, ...], False),
    ([[1]], tuple[int, ...], False), (3, tuple[int, ...] | None, False), ({}, dict, True),
    ([], dict, False), (object(), Any, True),
]


@pytest.mark.parametrize("value, annotation, expected", CASES)
def test_what_fits_each_annotation(value, annotation, expected) -> None:
    assert fits(value, annotation) is expected


def test_the_message_names_the_key_the_kind_wanted_and_the_kind_given() -> None:
    check_kinds(Example, {"duration": 2, "blocks": [1, 2], "settling": None, "unknown": {}})
    for values, message in (
            ({"duration": {"a": 1}}, "duration must be a number, got a table ({'a': 1})"),
            ({"blocks": 3}, "blocks must be a list of integers or absent, got an integer (3)"),
            ({"flag": 1}, "flag must be true or false, got an integer (1)"),
            ({"band": "x"}, "band must be a list of numbers, got a string ('x')"),
            ({"gate": [1]}, "gate must be a number or a string, got a list ([1])")):
        with pytest.raises(ValueError) as info:
            check_kinds(Example, values)
        assert str(info.value) == message
