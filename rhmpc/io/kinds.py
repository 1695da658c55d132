"""The kind of each value of a settings table, checked against its dataclass's annotations.

A run's settings come from TOML files and ``--set`` as numbers, strings, booleans, lists and
tables, and reach frozen dataclasses whose fields are annotated (``duration: float``,
``blocks: tuple[int, ...] | None``). :func:`check_kinds` compares each value with its field's
annotation before the dataclass is made, so that a table given where a number is set, a number
where a list is, or a boolean where a number is, is one line naming the key, not an error of
the arithmetic that meets it later. The kinds only: each class checks its own ranges, and
whether a number is whole.

An integer is a number; a boolean is neither (TOML's ``true`` is not 1); NumPy's scalars are
numbers and a one-dimensional array is a list, as code passes them.
"""

from __future__ import annotations

import functools
import numbers
import types
import typing
from typing import Any

__all__ = ["check_kinds", "fits", "kind_of"]

#: Each kind of value as a message names it.
_KIND_NAMES = {float: "a number", int: "an integer", str: "a string", bool: "true or false",
               dict: "a table", type(None): "absent"}


def kind_of(value: Any) -> str:
    """What ``value`` is, in words (as TOML writes it)."""
    if isinstance(value, bool):
        return "a boolean"
    for kind, name in ((numbers.Integral, "an integer"), (numbers.Real, "a number"),
                       (str, "a string"), (list | tuple, "a list"), (dict, "a table")):
        if isinstance(value, kind):
            return name
    return type(value).__name__


def _entries(value: Any) -> list | None:
    """The entries of a list, a tuple or a one-dimensional array; None for anything else."""
    if isinstance(value, list | tuple):
        return list(value)
    if getattr(value, "ndim", None) == 1:
        return list(value)
    return None


def fits(value: Any, annotation: Any) -> bool:
    """Whether ``value`` is of the kind ``annotation`` names (module docstring); a list's
    entries are checked against ``tuple[X, ...]``."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return any(fits(value, a) for a in typing.get_args(annotation))
    if origin is tuple:
        entries = _entries(value)
        kinds = [a for a in typing.get_args(annotation) if a is not Ellipsis]
        return entries is not None and all(any(fits(v, a) for a in kinds) for v in entries)
    if annotation is Any:
        return True
    if annotation in (float, int):  # whether a number is whole, the class checks
        return isinstance(value, numbers.Real) and not isinstance(value, bool) \
            and type(value).__name__ != "bool_"
    if annotation is type(None):
        return value is None
    return isinstance(value, origin or annotation)


def _wanted(annotation: Any) -> str:
    """The kind ``annotation`` names, in words."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_wanted(a) for a in typing.get_args(annotation))
    if origin is tuple:
        kinds = {_wanted(a) for a in typing.get_args(annotation) if a is not Ellipsis}
        return f"a list of {' or '.join(sorted(k.split(' ', 1)[-1] + 's' for k in kinds))}"
    return _KIND_NAMES.get(origin or annotation, getattr(annotation, "__name__", "?"))


@functools.cache
def _annotations(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def check_kinds(cls: type, values: dict[str, Any]) -> None:
    """Raise ``ValueError`` naming the first key of ``values`` whose value is not of the kind
    its field of the dataclass ``cls`` is annotated with ("duration must be a number, got a
    table ({'a': 1})"); keys ``cls`` has no field for are left to the caller."""
    annotations = _annotations(cls)
    for key, value in values.items():
        annotation = annotations.get(key)
        if annotation is not None and not fits(value, annotation):
            raise ValueError(f"{key} must be {_wanted(annotation)}, got {kind_of(value)} "
                             f"({value!r})")
