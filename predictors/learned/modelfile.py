"""The file of a fitted predictor: one format for every kind, one reader that checks it first.

A saved model is an ``.npz`` archive (NumPy's zip of ``.npy`` arrays: numbers only, nothing
that runs code when read) with a member ``header``, a JSON text::

    {"format": "rhmpc-model", "version": 1, "kind": "st-ridge", "dt": 0.04, "points": 4,
     "dim": 3, "settings": {...},
     "arrays": {"orders": {"shape": [5], "dtype": "<i8"}, "W0": {...}, ...}}

``kind`` is the predictor's name (:data:`rhmpc.predictors.registry.LEARNED`), ``dt`` the sampling
period it was fitted at [s], ``points`` and ``dim`` the tracked points and coordinates it reads,
``settings`` its settings dataclass, and ``arrays`` every other member with its shape and dtype.

:class:`ModelFile` checks, before any array is read: the file (a regular file of at most
``FILE_BYTES["model"]``, :mod:`rhmpc.io.reader`), the header (at most 4 MiB and 64 levels of
JSON, the format, a version this code reads, the kind asked for, a period, points and
dimension in range), and every declared array against its member (the same names, each
member's ``.npy`` header equal to its declaration, its length exact) with their total size
within ``FILE_BYTES["model"]``. The predictor then checks the shapes its settings imply
(:meth:`~rhmpc.predictors.learned.fitted.FittedPredictor.model_shapes`) before the arrays are read.
Every problem is one ``ValueError`` (:class:`rhmpc.io.FileError`) naming the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.io import FILE_BYTES, FileError, NpzArchive
from rhmpc.io.limits import size_bytes

__all__ = ["FORMAT", "MAX_POINTS", "VERSION", "ModelFile", "write_model"]

#: The format's name in every header.
FORMAT = "rhmpc-model"
#: The version written; a file of a later version is refused (written by a newer rhmpc).
VERSION = 1
#: The most tracked points, and coordinates per point, that a model may read.
MAX_POINTS, MAX_DIM = 64, 3
#: The most arrays a model holds (a network per lead and ensemble member, ~10 tensors each).
MAX_ARRAYS = 10_000


def write_model(path, kind: str, dt: float, points: int, dim: int, settings,
                arrays: dict[str, np.ndarray]) -> Path:
    """Write a model in the format above, atomically (:class:`rhmpc.io.AtomicFile`).

    ``settings``: the predictor's settings dataclass; ``arrays``: name → numeric array.
    """
    arrays = {k: np.asarray(v) for k, v in arrays.items()}
    header = {"format": FORMAT, "version": VERSION, "kind": kind, "dt": float(dt),
              "points": int(points), "dim": int(dim),
              "settings": dataclasses.asdict(settings),
              "arrays": {k: {"shape": list(v.shape), "dtype": v.dtype.str}
                         for k, v in arrays.items()}}
    with io.atomic_write(path) as f:
        np.savez(f, header=np.array(json.dumps(header, sort_keys=True)), **arrays)
    return Path(path)


def _field(path, header: dict, name: str, kind: type, low: float, high: float):
    value = header.get(name)
    if isinstance(value, bool) or not isinstance(value, kind if kind is float else int) \
            or not (low <= value <= high) or (kind is float and not math.isfinite(value)):
        raise FileError(f"{path}: the model's {name} {value!r} is not a "
                        f"{'period [s]' if kind is float else 'count'} in {low:g} … {high:g}")
    return kind(value)


class ModelFile:
    """A saved model opened and checked (module docstring); a context manager.

    Parameters
    ----------
    path : str or Path
        The file.
    expected_kind : str or sequence of str, optional
        The kind(s) of predictor asked for; another kind is refused, naming both.

    Attributes
    ----------
    kind, dt, points, dim, settings, shapes
        From the header; ``shapes``: name → (shape, dtype) of every array.
    """

    def __init__(self, path, expected_kind: str | tuple[str, ...] | None = None) -> None:
        self.path = Path(path)
        if self.path.is_file() and self.path.stat().st_size == 0:
            raise FileError(f"{self.path}: an empty file (0 bytes), not a saved model")
        self._npz = NpzArchive(self.path, "model")
        try:
            self._read_header(expected_kind)
        except BaseException:
            self._npz.close()
            raise

    def _read_header(self, expected_kind) -> None:
        path = self.path
        if "header" not in self._npz:
            raise FileError(f"{path}: not a saved rhmpc model (no header; a model saved by an "
                            "older version is fitted again with predict --save-models)")
        text = self._npz.read("header", FILE_BYTES["model header"])
        if text.dtype.kind != "U" or text.shape != ():
            raise FileError(f"{path}: the model's header is not a text")
        header = io.json_loads(str(text), f"{path}: the model's header")
        if not isinstance(header, dict) or header.get("format") != FORMAT:
            raise FileError(f"{path}: not a saved rhmpc model (its header is not {FORMAT}'s)")
        version = header.get("version")
        if not isinstance(version, int) or isinstance(version, bool) or not 1 <= version:
            raise FileError(f"{path}: the model's version {version!r} is not a version number")
        if version > VERSION:
            raise FileError(f"{path}: a model of format version {version}, written by a newer "
                            f"rhmpc; this one reads version {VERSION}")
        self.kind = header.get("kind")
        wanted = (expected_kind,) if isinstance(expected_kind, str) else expected_kind
        if not isinstance(self.kind, str) or (wanted and self.kind not in wanted):
            raise FileError(f"{path}: a {self.kind!r} model, not {' or '.join(map(repr, wanted))}"
                            if wanted else f"{path}: the model names no kind")
        self.dt = _field(path, header, "dt", float, 1e-6, 3600.0)
        self.points = _field(path, header, "points", int, 1, MAX_POINTS)
        self.dim = _field(path, header, "dim", int, 1, MAX_DIM)
        self.settings = header.get("settings")
        if not isinstance(self.settings, dict):
            raise FileError(f"{path}: the model's settings are not a table")
        self.shapes = self._declared(header.get("arrays"))

    def _declared(self, arrays) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
        """The declared arrays, checked against the members' own headers and sizes."""
        path = self.path
        if not isinstance(arrays, dict) or len(arrays) > MAX_ARRAYS:
            raise FileError(f"{path}: the model's header declares no table of arrays")
        members = set(self._npz.names) - {"header"}
        if set(arrays) != members:
            odd = sorted(set(arrays) ^ members)
            raise FileError(f"{path}: the model's arrays and its header disagree on "
                            f"{', '.join(odd[:5])}")
        shapes, total = {}, 0
        for name, spec in arrays.items():
            try:
                shape = tuple(int(n) for n in spec["shape"])
                dtype = np.dtype(str(spec["dtype"]))
            except (TypeError, ValueError, KeyError):
                raise FileError(f"{path}: array {name!r} is declared as {spec!r}, not a shape "
                                "and a dtype") from None
            if dtype.kind not in "fi" or any(n < 0 for n in shape):
                raise FileError(f"{path}: array {name!r} is declared {dtype} {shape}, not "
                                "numbers of a shape")
            held = self._npz.header(name)
            if held != (shape, dtype):
                raise FileError(f"{path}: array {name!r} holds {held[1]} {held[0]}, the "
                                f"model's header declares {dtype} {shape}: a damaged or "
                                "altered file")
            total += math.prod(shape) * dtype.itemsize
            shapes[name] = (shape, dtype)
        if total > FILE_BYTES["model"]:
            raise FileError(f"{path}: the model's arrays would take "
                            f"{size_bytes(total)}; at most {size_bytes(FILE_BYTES['model'])} "
                            "are loaded")
        return shapes

    def expect(self, shapes: dict[str, tuple[int, ...]], optional: tuple[str, ...] = ()) -> None:
        """Refuse the file unless its arrays are exactly ``shapes`` (name → shape), those of
        ``optional`` (present or not) aside."""
        have = {k: v[0] for k, v in self.shapes.items()}
        missing = sorted(set(shapes) - set(have))
        extra = sorted(set(have) - set(shapes) - set(optional))
        wrong = [k for k in shapes if k in have and have[k] != tuple(shapes[k])]
        if missing or extra or wrong:
            what = (f"lacks {missing[0]!r}" if missing else f"holds an unknown array "
                    f"{extra[0]!r}" if extra else f"holds {wrong[0]!r} of shape "
                    f"{have[wrong[0]]}, its settings make it {tuple(shapes[wrong[0]])}")
            raise FileError(f"{self.path}: the {self.kind} model {what}: a damaged or "
                            "altered file")

    def read(self, name: str) -> np.ndarray:
        """Array ``name`` (its declaration checked)."""
        return self._npz.read(name)

    def arrays(self) -> dict[str, np.ndarray]:
        """Every array, read."""
        return {name: self.read(name) for name in self.shapes}

    def close(self) -> None:
        self._npz.close()

    def __enter__(self) -> ModelFile:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
