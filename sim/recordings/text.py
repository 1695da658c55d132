"""CSV and NPZ recordings: read, write, and export any motion source to them.

CSV format
----------
A header line, then one sample per line::

    t,x,y,z              (or the 1-D form  t,x)
    0.0000,1.25,-0.40,3.10

Times are seconds and positions millimetres unless the header says otherwise with a unit
suffix on each name, ``t_s``/``t[s]``/``t (ms)``/``t_us``, ``x_mm``/``x [m]``/``x(um)``; or the
caller passes ``units=``. A file of several tracked points numbers them from 1, three columns each::

    t,x1,y1,z1,x2,y2,z2,x3,y3,z3

and is read point by point (:func:`sim.recordings.points.load_points`). Lines starting with
``#`` and blank lines are ignored. An empty position field or ``nan`` is a dropout and is kept
as missing (NaN); every other field must be a finite number. Time must be finite and strictly
increasing.

NPZ format
----------
Arrays ``t`` (n,) [s] and ``position`` (n, dim) (``x`` is accepted for ``position``) of real
numbers (complex ones are refused), and a string ``units`` (``"m"``, ``"mm"``, ``"um"`` or
``"cm"``) unless the caller passes ``units=``. Several tracked points: ``position`` of shape
(n, P, 3), or (n, 3P) with point p (from 1) in columns 3(p − 1) … 3p − 1.

Every problem raises :class:`~sim.recordings.recorded.RecordingError` naming the file, the line
(CSV) and what is wrong.
"""

from __future__ import annotations

import csv
import io
import re
import zipfile
import zlib
from pathlib import Path

import numpy as np

import boundary
from sim.heart.motion import MotionSource
from sim.recordings.recorded import (
    AXES,
    LENGTH_UNITS,
    TIME_UNITS,
    RecordedMotion,
    RecordingError,
    fail,
)

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
                  points: bool = False) -> tuple[int, float, str, str]:
    """(columns, time factor [s/unit], length unit, where the unit came from) from a header
    line (:data:`~sim.recordings.recorded.UNIT_ORIGINS`)."""
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
    return len(names) - 1, TIME_UNITS[t_key or "s"], unit, origin


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_csv(path: Path, units: str | None, points: bool = False) -> RecordedMotion:
    """A CSV recording (module docstring); ``points``: every column of a several-point file."""
    rows = _csv_rows(path)
    if not rows:
        raise fail(path, "empty file: no header and no samples")
    _, header = rows[0]
    dim, t_factor, unit, origin = _parse_header(path, header, units, points)
    factor = LENGTH_UNITS[unit]
    names = ["t", *AXES[:dim]] if dim <= 3 else _point_names(dim // 3)
    if len(rows) < 3:
        raise fail(path, f"needs at least two samples, found {len(rows) - 1}")
    t = np.empty(len(rows) - 1)
    z = np.empty((len(rows) - 1, dim))
    prev = -np.inf
    for k, (line, row) in enumerate(rows[1:]):
        if len(row) != dim + 1:
            raise fail(path, f"expected {dim + 1} fields ({','.join(names)}), "
                        f"got {len(row)}", line)
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
                raise fail(path, f"column {name}: {field!r} is not finite "
                            "(leave the field empty for a missing sample)", line)
            values.append(value)
        if not values[0] > prev:
            raise fail(path, f"time {values[0]:g} is not after the previous time "
                        f"{prev:g} (times must increase strictly)", line)
        prev = values[0]
        t[k] = values[0] * t_factor
        z[k] = np.asarray(values[1:]) * factor
    return RecordedMotion(t, z, str(path), unit, origin)


def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """The (line number, fields) of every line of a CSV file but comments and blank lines."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise fail(path, f"not a text file ({exc.reason})") from None
    reader = csv.reader(io.StringIO(text))
    try:
        return [(reader.line_num, row) for row in reader
                if row and not row[0].lstrip().startswith("#") and any(f.strip() for f in row)]
    except csv.Error as exc:
        limit = csv.field_size_limit()
        problem = (f"a field longer than {limit} characters" if "field larger" in str(exc)
                   else f"not a CSV line ({exc})")
        raise fail(path, problem, reader.line_num) from None


def read_npz(path: Path, units: str | None, points: bool = False) -> RecordedMotion:
    """An NPZ recording (module docstring); ``points``: every point of a several-point file."""
    t, z, pos_key, file_units = _npz_arrays(path)
    if t.ndim != 1:
        raise fail(path, f"'t' must be one-dimensional, got shape {t.shape}")
    shape = z.shape
    if z.ndim == 1:
        z = z[:, None]
    if z.ndim == 3 and z.shape[2] == 3:  # (n, P, 3): P tracked points
        z = z.reshape(z.shape[0], -1)
    if z.ndim != 2 or z.shape[0] != t.size or not (z.shape[1] == 1 or z.shape[1] % 3 == 0):
        raise fail(path, f"'{pos_key}' must have shape ({t.size}, 3) or ({t.size}, 1), or "
                   f"({t.size}, P, 3) or ({t.size}, 3P) for P tracked points; got {shape}")
    if z.shape[1] > 3 and not points:
        raise fail(path, f"'{pos_key}' holds {z.shape[1] // 3} tracked points; read them one "
                   "by one (point = 1, 2, …)")
    if t.size < 2:
        raise fail(path, f"needs at least two samples, found {t.size}")
    unit, origin = _npz_units(path, file_units, units)
    _check_times(path, t)
    if np.any(np.isinf(z)):
        row = int(np.flatnonzero(np.any(np.isinf(z), axis=1))[0])
        raise fail(path, f"sample {row}: position is infinite (use NaN for a missing sample)")
    return RecordedMotion(t, z * LENGTH_UNITS[unit], str(path), unit, origin)


def _npz_arrays(path: Path) -> tuple[np.ndarray, np.ndarray, str, str | None]:
    """``t``, the positions, their array's name and the file's ``units`` (None if absent).

    A file that is not a readable archive, or whose arrays are not real numbers (complex,
    text, objects), raises :class:`~sim.recordings.recorded.RecordingError`.
    """
    try:
        data = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise fail(path, f"not a readable .npz archive ({exc})") from None
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise fail(path, "holds a single .npy array, not an .npz archive of 't' and 'position'")
    with data:
        keys = set(data.files)
        pos_key = "position" if "position" in keys else "x" if "x" in keys else None
        if "t" not in keys or pos_key is None:
            raise fail(path, f"needs arrays 't' and 'position'; found {sorted(keys)}")
        try:  # the members are read (and decompressed) here
            t, z = data["t"], data[pos_key]
            file_units = str(data["units"]) if "units" in keys else None
        except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise fail(path, f"not a readable .npz archive ({exc})") from None
    return _real(path, "t", t), _real(path, pos_key, z), pos_key, file_units


def _real(path: Path, key: str, array: np.ndarray) -> np.ndarray:
    """``array`` as float; complex, text or object arrays are refused, naming ``key``."""
    kind = np.asarray(array).dtype.kind
    if kind == "c":
        raise fail(path, f"'{key}' holds complex numbers; positions and times must be real "
                   "(take the real part or the magnitude before saving)")
    if kind not in "fiub":
        raise fail(path, f"'{key}' holds {np.asarray(array).dtype} values, not numbers")
    return np.asarray(array, dtype=float)


def _npz_units(path: Path, file_units: str | None, units: str | None) -> tuple[str, str]:
    """The length unit of an NPZ file and its origin: the file's ``units``, else ``units``."""
    if units is not None and file_units is not None and units != file_units:
        raise fail(path, f"units {file_units!r} in the file disagree with the flag {units!r}")
    unit = file_units or units
    if unit is None:
        raise fail(path, "no 'units' array in the file and no units given (--units mm, m, um "
                   "or cm)")
    if unit not in LENGTH_UNITS:
        raise fail(path, f"unknown units {unit!r} (use one of {', '.join(sorted(LENGTH_UNITS))})")
    return unit, "file" if file_units is not None else "option"


def _check_times(path: Path, t: np.ndarray) -> None:
    """Refuse sample times that are not finite or do not increase strictly."""
    if not np.all(np.isfinite(t)):
        row = int(np.flatnonzero(~np.isfinite(t))[0])
        raise fail(path, f"sample {row}: time is not finite")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise fail(path, f"sample {bad[0] + 1}: time {t[bad[0] + 1]:g} is not after "
                    f"{t[bad[0]]:g} (times must increase strictly)")


def save_recording(path: str | Path, t: np.ndarray, z: np.ndarray,
                   comment: str | None = None) -> Path:
    """Write samples to ``path`` (.csv: seconds and millimetres; .npz: seconds and metres).

    Parameters
    ----------
    path : str or Path
        Destination; the suffix picks the format.
    t : ndarray, shape (n,)
        Sample times [s].
    z : ndarray, shape (n, dim)
        Positions [m], NaN for missing (written as empty CSV fields).
    comment : str, optional
        A ``#`` line written before the CSV header.
    """
    path = Path(path)
    t = np.asarray(t, dtype=float)
    z = np.asarray(z, dtype=float).reshape(t.size, -1)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with boundary.atomic_write(path) as fh:
            np.savez_compressed(fh, t=t, position=z, units=np.array("m"))
        return path
    if suffix not in {".csv", ".txt"}:
        raise RecordingError(f"{path}: unsupported file type {path.suffix!r} (use .csv or .npz)")
    axes = AXES[: z.shape[1]] if z.shape[1] in (1, 3) else None
    if axes is None:
        raise RecordingError(f"{path}: can only write 1-D or 3-D positions, got {z.shape[1]}")
    mm = z * 1e3
    with boundary.atomic_write(path, "w", newline="") as fh:
        if comment:
            fh.write(f"# {comment}\n")
        fh.write(",".join(["t_s", *(f"{a}_mm" for a in axes)]) + "\n")
        for ti, row in zip(t, mm, strict=True):
            fields = [f"{ti:.9f}"] + ["" if not np.isfinite(v) else f"{v:.6f}" for v in row]
            fh.write(",".join(fields) + "\n")
    return path


def export_source(source: MotionSource, path: str | Path, duration: float, rate: float,
                  t0: float = 0.0, comment: str | None = None) -> Path:
    """Sample ``source`` at ``rate`` [Hz] over ``[t0, t0 + duration)``, duration·rate samples
    (which read back as a recording of ``duration``), and save it to ``path``."""
    if not duration > 0 or not rate > 0:
        raise ValueError("duration and rate must be positive")
    n = max(1, round(duration * rate))
    t = t0 + np.arange(n) / rate
    return save_recording(path, t, np.asarray(source.position(t)).reshape(n, -1), comment)
