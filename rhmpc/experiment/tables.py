"""Settings dataclasses as the tables of a run's TOML file: to a plain ``dict`` and back.

:func:`to_dict` / :func:`from_dict` convert a frozen settings dataclass to and from a ``dict`` of
TOML-representable values (tuples become lists, ``None`` fields are left out);
:func:`replace_settings` changes some of its fields. Both check each value's kind against its
field's annotation first (:func:`rhmpc.io.check_kinds`): a table given where a number is set,
or a number where a list is, is one line naming the key rather than an error of the arithmetic
that meets it.
"""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

from rhmpc.io import check_kinds

S = TypeVar("S")


def to_dict(settings: Any) -> dict[str, Any]:
    """Settings dataclass → TOML-friendly ``dict`` (tuples → lists, ``None`` fields dropped)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if value is not None:
            out[f.name] = list(value) if isinstance(value, tuple) else value
    return out


def from_dict(cls: type[S], data: dict[str, Any]) -> S:
    """``dict`` (e.g. a parsed TOML table) → settings dataclass ``cls``.

    Raises
    ------
    ValueError
        On unknown keys or values the dataclass rejects.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{cls.__name__} must be a table, got {data!r}")
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(data) - set(names))
    if unknown:
        raise ValueError(f"unknown {cls.__name__} setting(s): {', '.join(unknown)}; "
                         f"valid: {', '.join(names)}")
    check_kinds(cls, data)
    kwargs = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    return cls(**kwargs)


def replace_settings(settings: S, changes: dict[str, Any]) -> S:
    """``dataclasses.replace`` with lists as tuples; a ValueError names the valid keys of an
    unknown one."""
    names = [f.name for f in dataclasses.fields(settings)]
    for key in changes:
        if key not in names:
            raise ValueError(f"unknown {type(settings).__name__} setting {key!r}; valid: "
                             f"{', '.join(names)}")
    check_kinds(type(settings), changes)
    return dataclasses.replace(settings, **{
        k: tuple(v) if isinstance(v, list) else v for k, v in changes.items()})
