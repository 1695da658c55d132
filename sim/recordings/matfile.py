"""MATLAB recordings: ``.mat`` v5 (scipy.io) and v7.3 (HDF5, h5py), as researchers keep them.

A recording is one numeric matrix (``var``) holding the three coordinates (or one) along one
axis and the samples along the other. ``rows``/``cols`` pick the coordinates when the matrix
holds more than three series; otherwise the axis of length 3 (or 1) is the coordinates' one.

Sample times
    A time vector in the file (``t``, ``time``, ``timestamps``, ``t_s``; seconds unless a
    string ``time_units`` says ``ms`` or ``us``), else a sample rate in the file (a scalar
    ``fs``, ``Fs``, ``FS``, ``rate``, ``sample_rate``, ``sampling_rate`` or ``fps`` [Hz]), else
    ``rate`` [Hz] (``--rate``). A ``rate`` that disagrees with the file's by more than 1 % is
    refused: one of them is wrong.
Length unit
    A string variable ``units`` in the file (``mm``, ``m``, ``um``, ``cm``) or ``units``
    (``--units``). One of them is required: unlike a CSV header, a MATLAB matrix carries no
    convention, and millimetres and centimetres are both plausible for heart motion, so no
    unit is assumed.

Every problem raises :class:`~rhmpc.sim.recordings.RecordingError` naming the file and the problem.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.sim.recordings.recorded import LENGTH_UNITS, TIME_UNITS, RecordedMotion, RecordingError

#: Names recognised as the time vector, in order of preference.
TIME_NAMES = ("t", "time", "timestamps", "t_s")
#: Names recognised as a scalar sample rate [Hz], in order of preference.
RATE_NAMES = ("fs", "Fs", "FS", "rate", "sample_rate", "sampling_rate", "fps")
#: Largest relative difference between a given rate and the file's own [-].
RATE_TOLERANCE = 0.01
#: At least this many samples [-].
MIN_SAMPLES = 2


def parse_indices(text: str) -> list[int]:
    """``"0,1,2"`` → [0, 1, 2] (the command lines' ``--rows``/``--cols``)."""
    import argparse

    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated indices, got {text!r}") from None


#: The longest text variable read (``units``, ``time_units``) [characters].
MAX_TEXT = 64
#: MATLAB classes of numeric arrays (a recording's matrix, its times, its rate).
NUMERIC = ("double", "single", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
           "uint64", "logical")


def _catalog(path: Path, f) -> tuple[str, dict[str, tuple[tuple[int, ...], str]]]:
    """The file's format (``"v5"`` or ``"hdf5"``, v7.3) and name → (MATLAB shape, class) of
    every variable, from the file's headers: no variable's data is read."""
    import h5py
    import scipy.io

    try:
        return "v5", {name: (tuple(shape), cls) for name, shape, cls in scipy.io.whosmat(f)}
    except NotImplementedError:  # v7.3: HDF5
        pass
    except (ValueError, TypeError, OSError, IndexError, EOFError,
            scipy.io.matlab.MatReadError) as exc:
        f.seek(0)
        if not _is_hdf5(f):  # an HDF5 file without MATLAB's header block is read as v7.3
            raise RecordingError(f"{path}: not a readable MATLAB file ({exc})") from None
    f.seek(0)
    out = {}
    try:
        with h5py.File(f, "r") as h5:
            for key, item in h5.items():
                if isinstance(item, h5py.Dataset) and not key.startswith("#"):
                    cls = item.attrs.get("MATLAB_class", b"double")
                    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
                    out[key] = (tuple(item.shape[::-1]), cls)  # HDF5 holds MATLAB's transpose
    except OSError as exc:
        raise RecordingError(f"{path}: not a readable MATLAB v7.3 file ({exc})") from None
    return "hdf5", out


#: HDF5's signature, at the start of its superblock: offset 0, 512, 1024, 2048, … (after a
#: user block, such as MATLAB's 512-byte header of a v7.3 file).
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _is_hdf5(f) -> bool:
    """Whether the open file ``f`` holds an HDF5 superblock where HDF5 looks for one."""
    offset = 0
    while True:
        f.seek(offset)
        head = f.read(len(HDF5_SIGNATURE))
        if head == HDF5_SIGNATURE:
            return True
        if len(head) < len(HDF5_SIGNATURE):
            return False
        offset = max(512, 2 * offset)


def _load(path: Path, f, kind: str, names: list[str]) -> dict[str, object]:
    """The variables ``names`` of the file (no other is read): numeric arrays (MATLAB's
    shape; complex ones kept, refused if read as positions) and strings."""
    import scipy.io

    f.seek(0)
    if kind == "v5":
        try:
            raw = scipy.io.loadmat(f, squeeze_me=False, chars_as_strings=True,
                                   variable_names=names)
        except (ValueError, TypeError, OSError, IndexError, EOFError,
                scipy.io.matlab.MatReadError) as exc:
            raise RecordingError(f"{path}: not a readable MATLAB file ({exc})") from None
    else:
        raw = _load_hdf5(path, f, names)
    out: dict[str, object] = {}
    for key, value in raw.items():
        if key.startswith("__") or not isinstance(value, np.ndarray):
            continue
        if value.dtype.kind in "US":
            out[key] = "".join(np.asarray(value).ravel().tolist()).strip()
        elif value.dtype.kind in "fiub":
            out[key] = np.asarray(value, dtype=float)
        elif value.dtype.kind == "c":
            out[key] = np.asarray(value, dtype=complex)
    return out


def _load_hdf5(path: Path, f, names: list[str]) -> dict[str, np.ndarray]:
    import h5py

    out = {}
    try:
        with h5py.File(f, "r") as h5:
            for key in names:
                item = h5[key]
                data = np.asarray(item[()])
                if item.attrs.get("MATLAB_class", b"") in (b"char", "char"):
                    out[key] = np.array("".join(chr(c) for c in data.ravel()))
                elif data.dtype.kind in "fiub":
                    out[key] = data.T  # HDF5 holds MATLAB's transpose
    except OSError as exc:
        raise RecordingError(f"{path}: not a readable MATLAB v7.3 file ({exc})") from None
    return out


def _select(path: Path, a: np.ndarray, var: str, rows, cols, points: bool = False) -> np.ndarray:
    """(n, dim) samples of matrix ``a`` with coordinates ``rows`` or ``cols``; ``points``: also
    (n, 3P) for P tracked points along the shorter axis (x1, y1, z1, x2, …)."""
    if a.ndim != 2:
        raise RecordingError(f"{path}: variable {var!r} has shape {a.shape}; expected a matrix "
                             "(coordinates × samples or samples × coordinates)")
    if rows is not None and cols is not None:
        raise RecordingError(f"{path}: give the coordinates as rows or as columns, not both")
    if rows is not None or cols is not None:
        pick = list(rows if rows is not None else cols)
        axis_len = a.shape[0] if rows is not None else a.shape[1]
        bad = [i for i in pick if not 0 <= i < axis_len]
        if len(pick) not in (1, 3) or bad:
            raise RecordingError(
                f"{path}: variable {var!r} has shape {a.shape}; cannot take "
                f"{'rows' if rows is not None else 'columns'} {pick} as 1 or 3 coordinates "
                "(0-based)")
        return a[pick].T if rows is not None else a[:, pick]
    if a.shape[1] in (1, 3) and a.shape[0] > 3:
        return a
    if a.shape[0] in (1, 3) and a.shape[1] > 3:
        return a.T
    short = int(np.argmin(a.shape))
    if a.shape[short] % 3 == 0 and a.shape[short] < a.shape[1 - short]:
        if points:
            return a if short == 1 else a.T
        raise RecordingError(f"{path}: variable {var!r} has shape {a.shape}: "
                             f"{a.shape[short] // 3} tracked points of 3 coordinates; read them "
                             "one by one (point = 1, 2, …) or give --rows or --cols")
    raise RecordingError(f"{path}: variable {var!r} has shape {a.shape}: which axis holds "
                         "the coordinates is ambiguous; give --rows or --cols")


def load_mat(path: str | Path, var: str | None = None, rows=None, cols=None,
             rate: float | None = None, units: str | None = None,
             points: bool = False) -> RecordedMotion:
    """Load a MATLAB recording (module docstring).

    Parameters
    ----------
    path : str or Path
        ``.mat`` file, v5 or v7.3.
    var : str, optional
        The variable holding the positions; optional when the file has only one matrix
        besides the time vector.
    rows, cols : sequence of int, optional
        0-based rows (samples along columns) or columns (samples along rows) holding x, y, z.
    rate : float, optional
        Sample rate [Hz]; required when the file holds neither a time vector nor a rate, and
        refused when it disagrees with the file's by more than :data:`RATE_TOLERANCE`.
    units : str, optional
        Length unit (``m``, ``mm``, ``um``, ``cm``); required when the file does not state it.
    points : bool
        Accept a matrix of several tracked points: 3P coordinates (x1, y1, z1, x2, …) along
        its shorter axis, returned as (n, 3P) (:func:`rhmpc.sim.recordings.points.load_points`).

    Returns
    -------
    RecordedMotion
        Times in seconds from 0 (or the file's time vector), positions in metres.
    """
    path = Path(path)
    with io.open_input(path, "recording") as f:
        kind, catalog = _catalog(path, f)
        numeric = {k: shape for k, (shape, cls) in catalog.items() if cls in NUMERIC}
        time_key = next((k for k in TIME_NAMES if k in numeric), None)
        var = _variable(path, numeric, var, time_key)
        wanted = [var, *(k for k in (time_key, *RATE_NAMES) if k in numeric)]
        for name in wanted:  # three values make a sample of positions
            io.check("samples", math.prod(numeric[name]) // 3, f"{path}: {name!r}")
        wanted += [k for k in ("units", "time_units") if catalog.get(k, ((), ""))[1] == "char"
                   and math.prod(catalog[k][0]) <= MAX_TEXT]
        variables = _load(path, f, kind, list(dict.fromkeys(wanted)))
    arrays = {k: v for k, v in variables.items() if isinstance(v, np.ndarray)}
    if var not in arrays:
        raise RecordingError(f"{path}: variable {var!r} could not be read as numbers")
    if arrays[var].dtype.kind == "c":
        raise RecordingError(f"{path}: variable {var!r} holds complex numbers; positions must "
                             "be real (take the real part or the magnitude before saving)")
    z = _select(path, arrays[var], var, rows, cols, points)
    n = z.shape[0]
    if n < MIN_SAMPLES:
        raise RecordingError(f"{path}: variable {var!r} has {n} sample(s); at least "
                             f"{MIN_SAMPLES} are needed")
    time_key = None if time_key == var else time_key
    t = _times(path, variables, time_key, n, rate)
    if np.any(np.isinf(z)):
        raise RecordingError(f"{path}: {var!r} has infinite values (use NaN for missing)")
    if not np.any(np.all(np.isfinite(z), axis=1)):
        raise RecordingError(f"{path}: {var!r} has no complete sample (all NaN)")
    unit, origin = _units(path, variables.get("units"), units)
    stated = variables.get("time_units") if time_key is not None else "s"  # "s": from a rate
    return RecordedMotion(t, z * LENGTH_UNITS[unit], str(path), unit, origin,
                          stated if isinstance(stated, str) else None)


def _variable(path: Path, numeric: dict[str, tuple[int, ...]], var: str | None,
              time_key: str | None) -> str:
    """The variable holding the positions: ``var``, or the file's only numeric matrix besides
    the time vector (``numeric``: name → shape)."""
    if var is None:
        candidates = [k for k, shape in numeric.items() if k != time_key
                      and int(np.prod(shape)) > 3]
        if len(candidates) != 1:
            raise RecordingError(f"{path}: name the variable with --var (found "
                                 f"{', '.join(sorted(numeric)) or 'no numeric variables'})")
        var = candidates[0]
    if var not in numeric:
        raise RecordingError(f"{path}: no numeric variable {var!r} (found "
                             f"{', '.join(sorted(numeric)) or 'none'})")
    return var


def _times(path: Path, variables: dict[str, object], time_key: str | None, n: int,
           rate: float | None) -> np.ndarray:
    """The n sample times [s]: the file's time vector, else its rate, else ``rate``."""
    if rate is not None and not (np.isfinite(rate) and rate > 0):
        raise RecordingError(f"{path}: the sample rate must be positive, got {rate}")
    if time_key is not None:
        t = _time_vector(path, variables, time_key, n)
        _agree(path, f"the time vector {time_key!r}", 1.0 / np.median(np.diff(t)), rate)
        return t
    rate_key = next((k for k in RATE_NAMES if _scalar(variables.get(k)) is not None), None)
    if rate_key is not None:
        file_rate = _scalar(variables[rate_key])
        if not (np.isfinite(file_rate) and file_rate > 0):
            raise RecordingError(f"{path}: the sample rate {rate_key!r} in the file must be "
                                 f"positive, got {file_rate:g}")
        _agree(path, f"the rate {rate_key!r}", file_rate, rate)
        return np.arange(n) / file_rate
    if rate is None:
        raise RecordingError(
            f"{path}: the file has no sample times: give the sample rate with --rate HZ (e.g. "
            f"--rate 25), or store a time vector ({', '.join(TIME_NAMES)}) [s] or a rate "
            f"({', '.join(RATE_NAMES[:2])}) [Hz] in the file")
    return np.arange(n) / float(rate)


def _time_vector(path: Path, variables: dict[str, object], key: str, n: int) -> np.ndarray:
    """The time vector ``key`` in seconds (its ``time_units``), checked: n finite samples that
    increase strictly."""
    unit = variables.get("time_units", "s")
    if not isinstance(unit, str) or unit not in TIME_UNITS:
        raise RecordingError(f"{path}: time_units {unit!r} is not a time unit "
                             f"(use one of {', '.join(TIME_UNITS)})")
    t = np.asarray(variables[key]).ravel() * TIME_UNITS[unit]
    if t.size != n:
        raise RecordingError(f"{path}: time vector {key!r} has {t.size} samples, the "
                             f"positions have {n}")
    if not np.all(np.isfinite(t)):
        raise RecordingError(f"{path}: time vector {key!r} is not finite everywhere")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise RecordingError(f"{path}: time vector {key!r} does not increase at "
                             f"sample {bad[0] + 1} ({t[bad[0] + 1]:g} after {t[bad[0]]:g})")
    return t


def _agree(path: Path, what: str, file_rate: float, rate: float | None) -> None:
    """Refuse a given ``rate`` that differs from the file's own by more than the tolerance."""
    if rate is not None and abs(rate / file_rate - 1.0) > RATE_TOLERANCE:
        raise RecordingError(
            f"{path}: --rate {rate:g} Hz disagrees with {what} in the file ({file_rate:.6g} "
            "Hz); leave --rate out, or correct the file (a time vector not in seconds needs "
            "time_units 'ms' or 'us')")


def _scalar(value: object) -> float | None:
    """A one-element real numeric array's value, else None."""
    if isinstance(value, np.ndarray) and value.size == 1 and value.dtype.kind == "f":
        return float(value.ravel()[0])
    return None


def _units(path: Path, file_units: object, units: str | None) -> tuple[str, str]:
    """The length unit and where it came from: the file's ``units``, else ``units``, else
    millimetres, the format's default as for CSV (:mod:`rhmpc.sim.recordings.plausible` warns,
    naming the likely unit, when the motion's span is implausible in it)."""
    if isinstance(file_units, str) and units is not None and file_units != units:
        raise RecordingError(f"{path}: units {file_units!r} in the file disagree with {units!r}")
    if file_units is None and units is None:
        return "mm", "default"
    unit = file_units if isinstance(file_units, str) else units
    if unit not in LENGTH_UNITS:
        raise RecordingError(f"{path}: unknown units {unit!r} "
                             f"(use one of {', '.join(sorted(LENGTH_UNITS))})")
    return unit, "file" if isinstance(file_units, str) else "option"
