"""Per-tick records of a run: a fixed-size decimated trace in memory, every tick on disk.

The loop hands each chunk of ticks to both as a dict of arrays of equal length (``tick``, ``time``
[s], ``ee``, ``poi``, ``reference0`` (n, 3) [m], ``tau_mpc``, ``tau`` (n, nv) [N·m], ``tick_ns``).

:class:`TraceFile` writes ``--trace FILE`` as the run goes: an NPZ archive (a zip of ``.npy``
members, ``np.load`` opens it) with one member per field and chunk, ``<field>.<chunk:06d>``,
plus ``fields`` and ``chunks``; :func:`read_trace` concatenates the chunks into one array per field.
Memory: one chunk. The archive is written to a temporary file beside ``FILE`` and renamed over it
when the run closes it (:class:`rhmpc.io.AtomicFile`); after a failed write it is dropped and a
previous ``FILE`` stays.
"""

from __future__ import annotations

import contextlib
import zipfile
from pathlib import Path

import numpy as np

from rhmpc.io import AtomicFile
from rhmpc.io.npz import NpzArchive


class DecimatedTrace:
    """Every ``stride``-th tick of the run plus every tick of the last ``tail`` ticks (and the
    ticks a chunk flags: those next to a recording's sample, where the run is scored).

    ``stride = ⌈n_ticks / points⌉``, so the trace holds at most ``points + tail`` ticks whatever
    the run length (for ``--plot``: the whole run, and a full-rate window at its end).
    """

    def __init__(self, n_ticks: int, points: int = 20_000, tail: int = 4_000) -> None:
        self.stride = max(1, -(-int(n_ticks) // points))
        self.tail = int(tail)
        self._kept: list[dict] = []
        self._recent: list[dict] = []

    def add(self, chunk: dict[str, np.ndarray], also: np.ndarray | None = None) -> None:
        """Keep the chunk's every ``stride``-th tick, and the ticks flagged in ``also``."""
        keep = chunk["tick"] % self.stride == 0
        if also is not None:
            keep |= also
        self._kept.append({k: v[keep] for k, v in chunk.items()})
        self._recent.append(chunk)
        while sum(c["tick"].size for c in self._recent[1:]) >= self.tail:
            self._recent.pop(0)

    def arrays(self) -> dict[str, np.ndarray]:
        """One array per field, ticks in order (decimated, then the full-rate tail)."""
        if not self._kept:
            return {}
        recent = {k: np.concatenate([c[k] for c in self._recent]) for k in self._recent[0]}
        recent = {k: v[-self.tail:] for k, v in recent.items()} if self.tail else \
            {k: v[:0] for k, v in recent.items()}
        first = recent["tick"][0] if recent["tick"].size else np.inf
        kept = {k: np.concatenate([c[k] for c in self._kept]) for k in self._kept[0]}
        before = kept["tick"] < first
        return {k: np.concatenate((kept[k][before], recent[k])) for k in kept}


class TraceFile:
    """Every tick of a run written to an NPZ archive chunk by chunk (see the module docstring)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._out = AtomicFile(self.path)
        self._zip = zipfile.ZipFile(self._out.file, "w", compression=zipfile.ZIP_STORED,
                                    allowZip64=True)
        self._failed = False
        self._chunks = 0
        self._fields: list[str] | None = None

    def _member(self, name: str, array: np.ndarray) -> None:
        try:
            with self._zip.open(name + ".npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.ascontiguousarray(array), allow_pickle=False)
        except OSError as exc:
            self._failed = True
            raise self._out.error(exc) from None

    def add(self, chunk: dict[str, np.ndarray]) -> None:
        if self._fields is None:
            self._fields = list(chunk)
        for name in self._fields:
            self._member(f"{name}.{self._chunks:06d}", chunk[name])
        self._chunks += 1

    def close(self) -> None:
        """Finish the archive and put it in place (drop it after a failed write)."""
        if self._failed:
            with contextlib.suppress(Exception):  # its end record cannot be written either
                self._zip.close()
            self._out.discard()
            return
        try:
            self._member("fields", np.array(self._fields or [], dtype="U32"))
            self._member("chunks", np.array(self._chunks))
            self._zip.close()
        except BaseException:
            self._out.discard()
            raise
        self._out.commit()


def read_trace(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a :class:`TraceFile`, one per field over every tick of the run."""
    with NpzArchive(path, "trace") as npz:
        fields, chunks = [str(f) for f in npz.read("fields")], int(npz.read("chunks").item())
        return {f: np.concatenate([npz.read(f"{f}.{c:06d}") for c in range(chunks)])
                if chunks else np.empty(0) for f in fields}
