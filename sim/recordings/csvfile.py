"""CSV recordings, read in blocks through the one reader.

A header line, then one sample per line::

    t,x,y,z              (or the 1-D form  t,x)
    0.0000,1.25,-0.40,3.10

The time column may be named as in a MATLAB file (``time``, ``timestamps``). Times are seconds
and positions millimetres unless the header says otherwise with a unit
suffix on each name, ``t_s``/``t[s]``/``t (ms)``/``t_us``, ``x_mm``/``x [m]``/``x(um)``; or the
caller passes ``units=``. A file of several tracked points numbers them from 1, three columns each::

    t,x1,y1,z1,x2,y2,z2,x3,y3,z3

and is read point by point (:func:`rhmpc.sim.recordings.points.load_points`). Lines starting with
``#`` and blank lines are ignored. An empty position field or ``nan`` is a dropout and is kept
as missing (NaN); every other field must be a finite number. Time must be finite and strictly
increasing.

The file is opened by :func:`rhmpc.io.open_input` (a regular file of at most
``FILE_BYTES["recording"]``), its lines are counted first and bounded (``BOUNDS["samples"]``),
then it is read in blocks of :data:`BLOCK_BYTES`, each parsed by NumPy's parser
(:func:`numpy.loadtxt`) and, should that fail, line by line to name the line and the problem.
Every problem raises :class:`~rhmpc.sim.recordings.recorded.RecordingError` naming the file, the
line and what is wrong.
"""

from __future__ import annotations

import csv
import re
from io import StringIO
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.sim.recordings.matfile import TIME_NAMES
from rhmpc.sim.recordings.recorded import (
    AXES,
    LENGTH_UNITS,
    TIME_UNITS,
    RecordedMotion,
    RecordingError,
    fail,
)

__all__ = ["BLOCK_BYTES", "read_csv"]

#: Bytes of the file parsed at a time.
BLOCK_BYTES = 1 << 24
#: The longest line read [bytes]: a sample of 64 points is about 2 kB.
MAX_LINE = 1 << 20
#: A comma before an empty field (a dropout), to be read as NaN by NumPy's parser (an empty
#: first field, a missing time, is refused by the careful parser).
_EMPTY = re.compile(r",(?=[ \t]*(?:,|$))", re.M)

_HEADER_FIELD = re.compile(
    r"^\s*(?P<name>[A-Za-z]+\d*)\s*(?:(?:_|\[|\()\s*(?P<unit>[A-Za-zµ]+)\s*[\])]?)?\s*$")


def _unit_key(path: Path, name: str, unit: str | None, table: dict[str, float]) -> str | None:
    """The key of ``table`` that a header's ``unit`` names (None when it names none)."""
    if unit is None:
        return None
    key = unit.lower() if unit.lower() in table else unit
    if key not in table:
        raise fail(path, f"unknown unit {unit!r} for column {name!r} "
                    f"(use one of {', '.join(sorted(table))})", 1)
    return key


def _point_names(count: int) -> list[str]:
    """``t, x1, y1, z1, …`` for ``count`` tracked points."""
    return ["t", *(f"{a}{p}" for p in range(1, count + 1) for a in AXES)]


def _columns_ok(names: list[str], points: bool) -> bool:
    """Whether header ``names`` are t,x / t,x,y,z, or (``points``) t,x1,y1,z1,…,xP,yP,zP."""
    if names in (["t", "x"], ["t", "x", "y", "z"], _point_names(1)):
        return True
    return points and (len(names) - 1) % 3 == 0 and names == _point_names((len(names) - 1) // 3)


def _parse_header(path: Path, fields: list[str], units: str | None,
                  points: bool = False) -> tuple[int, str | None, str, str]:
    """(columns, the time unit it states or None, length unit, where the length unit came
    from) of a header line (:data:`~rhmpc.sim.recordings.recorded.UNIT_ORIGINS`)."""
    if all(_looks_numeric(f) for f in fields):
        raise fail(path, "missing header line: the first line must name the columns "
                    "(t,x,y,z or t,x)", 1)
    parsed = []
    for raw in fields:
        m = _HEADER_FIELD.match(raw)
        if not m:
            raise fail(path, f"bad header field {raw.strip()!r}: expected t, x, y, z "
                        "optionally with a unit such as x_mm or x [mm]", 1)
        parsed.append((m.group("name").lower(), m.group("unit")))
    if parsed[0][0] in TIME_NAMES:  # the time column under a MATLAB file's names: t, time, …
        parsed[0] = ("t", parsed[0][1])
    names = [n for n, _ in parsed]
    if not _columns_ok(names, points):
        several = _columns_ok(names, True)
        raise fail(path, f"header columns {','.join(names)} "
                   + ("hold several tracked points: read them one by one (point = 1, 2, …)"
                      if several else "are not t,x,y,z or t,x (or t,x1,y1,z1,x2,… for several "
                      "tracked points)"), 1)
    t_key = _unit_key(path, "t", parsed[0][1], TIME_UNITS)
    lengths = {_unit_key(path, n, u, LENGTH_UNITS) for n, u in parsed[1:]}
    if len(lengths) > 1:
        raise fail(path, "position columns have different units (or only some state one)", 1)
    header_unit = lengths.pop()
    if units is not None and units not in LENGTH_UNITS:
        raise RecordingError(f"{path}: unknown units flag {units!r} "
                             f"(use one of {', '.join(sorted(LENGTH_UNITS))})")
    if header_unit is not None and units is not None \
            and LENGTH_UNITS[header_unit] != LENGTH_UNITS[units]:
        raise fail(path, f"header units disagree with the units flag {units!r}", 1)
    unit, origin = ((header_unit, "file") if header_unit is not None
                    else (units, "option") if units is not None else ("mm", "default"))
    return len(names) - 1, t_key, unit, origin


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_csv(path: Path, units: str | None, points: bool = False) -> RecordedMotion:
    """A CSV recording (module docstring); ``points``: every column of a several-point file."""
    with io.open_input(path, "recording") as f:
        lines = sum(block.count(b"\n") for block in iter(lambda: f.read(BLOCK_BYTES), b""))
        io.check("samples", lines, str(path))
        f.seek(0)
        reader = _Blocks(path, f)
        header = reader.header()
        dim, t_unit, unit, origin = _parse_header(path, header, units, points)
        t, z = reader.samples(dim)
    if t.size < 2:
        raise fail(path, f"needs at least two samples, found {t.size}")
    return RecordedMotion(t * TIME_UNITS[t_unit or "s"], z * LENGTH_UNITS[unit], str(path),
                          unit, origin, t_unit)


class _Blocks:
    """The lines of a CSV file, a block at a time: its header, then its samples."""

    def __init__(self, path: Path, f) -> None:
        self.path, self._f = path, f
        self._pending: list[str] = []  # lines read but not parsed yet
        self._left = b""  # the start of a line cut by the block's end
        self._first = True
        self.line = 0  # the number of the last line handed out

    def _read(self) -> bool:
        """Read a block of whole lines into ``_pending``; False at the end of the file."""
        data = self._f.read(BLOCK_BYTES)
        if not data and not self._left:
            return False
        data, cut = self._left + data, (self._left + data).rfind(b"\n") if data else -2
        if cut == -1 and len(data) > MAX_LINE:
            raise fail(self.path, f"a line longer than {MAX_LINE} bytes: not a CSV recording",
                       self.line + len(self._pending) + 1)
        self._left = b"" if cut == -2 else data[cut + 1:]
        if cut != -2:
            data = data[: cut + 1]
        try:
            text = data.decode("utf-8-sig" if self._first else "utf-8")
        except UnicodeDecodeError as exc:
            raise fail(self.path, f"not a text file ({exc.reason})") from None
        self._first = False
        self._pending += text.splitlines()
        return True

    def header(self) -> list[str]:
        """The fields of the first line that is neither blank nor a comment."""
        while True:
            while self._pending:
                raw = self._pending.pop(0)
                self.line += 1
                row = next(csv.reader([raw]), [])
                if row and not row[0].lstrip().startswith("#") and any(f.strip() for f in row):
                    return row
            if not self._read():
                raise fail(self.path, "empty file: no header and no samples")

    def samples(self, dim: int) -> tuple[np.ndarray, np.ndarray]:
        """Times (n,) and positions (n, dim) of every sample line, in the file's units."""
        names = ["t", *AXES[:dim]] if dim <= 3 else _point_names(dim // 3)
        parts, prev = [], -np.inf
        while self._pending or self._read():
            lines, first = self._pending, self.line + 1
            self._pending, self.line = [], self.line + len(lines)
            block = _fast(lines, dim, prev)
            if block is None:
                block = _careful(self.path, lines, first, names, prev)
            if block.size:
                parts.append(block)
                prev = block[-1, 0]
        rows = np.concatenate(parts) if parts else np.empty((0, dim + 1))
        return rows[:, 0], rows[:, 1:]


def _fast(lines: list[str], dim: int, prev: float) -> np.ndarray | None:
    """The block's samples (n, dim + 1) by NumPy's parser (empty fields, dropouts, read as
    NaN), or None when it cannot read them or they break a rule (the careful parser then says
    where)."""
    text = "\n".join(lines)
    rows = None
    for attempt in (lambda: text, lambda: _EMPTY.sub(",nan", text)):  # dropouts, if need be
        try:
            rows = np.loadtxt(StringIO(attempt()), delimiter=",", comments="#", ndmin=2,
                              dtype=float)
            break
        except (ValueError, IndexError):
            continue
    if rows is None:
        return None
    if rows.size == 0:
        return np.empty((0, dim + 1))
    t = rows[:, 0]
    if rows.shape[1] != dim + 1 or np.isinf(rows).any() or not np.isfinite(t).all() \
            or not t[0] > prev or np.any(np.diff(t) <= 0):
        return None
    return rows


def _careful(path: Path, lines: list[str], first: int, names: list[str],
             prev: float) -> np.ndarray:
    """The block's samples line by line; the first problem raises, naming its line."""
    dim = len(names) - 1
    out = []
    reader = csv.reader(lines)
    try:
        for row in reader:
            line = first + reader.line_num - 1
            if not row or row[0].lstrip().startswith("#") or not any(f.strip() for f in row):
                continue
            values = _values(path, row, names, line)
            if not values[0] > prev:
                raise fail(path, f"time {values[0]:g} is not after the previous time "
                           f"{prev:g} (times must increase strictly)", line)
            prev = values[0]
            out.append(values)
    except csv.Error as exc:
        limit = csv.field_size_limit()
        problem = (f"a field longer than {limit} characters" if "field larger" in str(exc)
                   else f"not a CSV line ({exc})")
        raise fail(path, problem, first + reader.line_num - 1) from None
    return np.array(out, dtype=float).reshape(-1, dim + 1)


def _values(path: Path, row: list[str], names: list[str], line: int) -> list[float]:
    """The numbers of one sample line (NaN for a dropout), checked."""
    if len(row) != len(names):
        raise fail(path, f"expected {len(names)} fields ({','.join(names)}), got {len(row)}",
                   line)
    values = []
    for name, field in zip(names, row, strict=True):
        field = field.strip()
        if field == "" or field.lower() == "nan":
            if name == "t":
                raise fail(path, "time is missing; only positions may be missing", line)
            values.append(np.nan)
            continue
        try:
            value = float(field)
        except ValueError:
            raise fail(path, f"column {name}: {field!r} is not a number", line) from None
        if not np.isfinite(value):
            raise fail(path, f"column {name}: {field!r} is not finite (leave the field empty "
                       "for a missing sample)", line)
        values.append(value)
    return values
