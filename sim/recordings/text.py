"""NPZ recordings, and writing recordings: CSV and NPZ files of any motion source.

NPZ format
----------
Arrays ``t`` (n,) [s] and ``position`` (n, dim) (``x`` is accepted for ``position``) of real
numbers (complex ones are refused), and a string ``units`` (``"m"``, ``"mm"``, ``"um"`` or
``"cm"``) unless the caller passes ``units=``. Several tracked points: ``position`` of shape
(n, P, 3), or (n, 3P) with point p (from 1) in columns 3(p − 1) … 3p − 1. The archive is read
through :class:`rhmpc.io.NpzArchive` (each array's header checked before its data; nothing
unpickled) and its arrays bounded by ``BOUNDS["samples"]``.

CSV files are read by :mod:`rhmpc.sim.recordings.csvfile`. Every problem raises
:class:`~rhmpc.sim.recordings.recorded.RecordingError` naming the file and what is wrong. Files are
written atomically (:class:`rhmpc.io.AtomicFile`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.sim.heart.motion import MotionSource
from rhmpc.sim.recordings.recorded import (
    AXES,
    LENGTH_UNITS,
    RecordedMotion,
    RecordingError,
    fail,
)


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


#: The most tracked points an NPZ recording may hold.
MAX_POINTS = 64


def _npz_arrays(path: Path) -> tuple[np.ndarray, np.ndarray, str, str | None]:
    """``t``, the positions, their array's name and the file's ``units`` (None if absent).

    A file that is not a readable archive, whose arrays are not real numbers (complex, text,
    objects) or hold more samples than fit (``BOUNDS["samples"]``), raises
    :class:`~rhmpc.sim.recordings.recorded.RecordingError`.
    """
    try:
        with io.NpzArchive(path, "recording") as data:
            keys = set(data.names)
            pos_key = "position" if "position" in keys else "x" if "x" in keys else None
            if "t" not in keys or pos_key is None:
                raise fail(path, f"needs arrays 't' and 'position'; found {sorted(keys)}")
            shape, _ = data.header("t")
            io.check("samples", int(np.prod(shape)), f"{path}: 't'")
            limit = 16 * int(np.prod(shape)) * 3 * MAX_POINTS  # complex, every point
            t, z = data.read("t", 16 * int(np.prod(shape))), data.read(pos_key, limit)
            file_units = str(data.read("units", 1024)) if "units" in keys else None
    except io.FileError as exc:
        raise RecordingError(str(exc)) from None
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
        with io.atomic_write(path) as fh:
            np.savez_compressed(fh, t=t, position=z, units=np.array("m"))
        return path
    if suffix not in {".csv", ".txt"}:
        raise RecordingError(f"{path}: unsupported file type {path.suffix!r} (use .csv or .npz)")
    axes = AXES[: z.shape[1]] if z.shape[1] in (1, 3) else None
    if axes is None:
        raise RecordingError(f"{path}: can only write 1-D or 3-D positions, got {z.shape[1]}")
    mm = z * 1e3
    with io.atomic_write(path, "w", newline="") as fh:
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
