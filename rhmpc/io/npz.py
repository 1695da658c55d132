"""NumPy ``.npz`` archives read through the one way in, member by member.

An ``.npz`` file is a zip archive of ``.npy`` members. :class:`NpzArchive` opens it with
:func:`rhmpc.io.reader.open_input`, reads each member's header (its dtype and shape) before its
data, and reads the data only when the member is what its header says: numbers or text (never
Python objects, so nothing is unpickled), no larger than asked, and exactly as long in the
archive as the header makes it (a truncated or padded member is refused before it is read).
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from rhmpc.io.limits import size_bytes
from rhmpc.io.reader import FileError, open_input

__all__ = ["NpzArchive"]

#: What a damaged archive raises while it is read.
_DAMAGE = (zipfile.BadZipFile, zlib.error, EOFError, ValueError, OSError, KeyError,
           NotImplementedError, RuntimeError)


class NpzArchive:
    """The arrays of an ``.npz`` file, read one at a time (module docstring); a context
    manager.

    Parameters
    ----------
    path : str or Path
        The archive.
    kind : str
        Its kind of file (:data:`rhmpc.io.limits.FILE_BYTES`), for its largest size.

    Raises
    ------
    FileError
        An empty file, a single ``.npy`` array, or a file that is not a readable zip archive.
    """

    def __init__(self, path: str | Path, kind: str = "file") -> None:
        self.path = Path(path)
        self._file = open_input(self.path, kind)
        try:
            head = self._file.read(6)
            if not head:
                raise FileError(f"{self.path}: an empty file, not an .npz archive")
            if head == b"\x93NUMPY":
                raise FileError(f"{self.path}: holds a single .npy array, not an .npz archive")
            self._file.seek(0)
            self._zip = zipfile.ZipFile(self._file)
            self._members = {i.filename.removesuffix(".npy"): i for i in self._zip.infolist()
                             if i.filename.endswith(".npy")}
        except FileError:
            self._file.close()
            raise
        except _DAMAGE as exc:
            self._file.close()
            raise self.damaged(exc) from None
        except BaseException:
            self._file.close()
            raise

    def damaged(self, exc: BaseException) -> FileError:
        """The error of a damaged archive (``exc``: what reading it raised)."""
        return FileError(f"{self.path}: not a readable .npz archive ({exc})")

    @property
    def names(self) -> list[str]:
        """The arrays' names, in the archive's order."""
        return list(self._members)

    def __contains__(self, name: str) -> bool:
        return name in self._members

    def header(self, name: str) -> tuple[tuple[int, ...], np.dtype]:
        """(shape, dtype) of array ``name``, from its header only."""
        info = self._member(name)
        try:
            with self._zip.open(info) as f:
                shape, dtype, _, _ = self._read_header(f)
        except _DAMAGE as exc:
            raise self.damaged(exc) from None
        return shape, dtype

    def _member(self, name: str) -> zipfile.ZipInfo:
        if name not in self._members:
            raise FileError(f"{self.path}: holds no array {name!r} (it holds "
                            f"{', '.join(self.names) or 'none'})")
        return self._members[name]

    @staticmethod
    def _read_header(f) -> tuple[tuple[int, ...], np.dtype, bool, int]:
        version = np.lib.format.read_magic(f)
        reader = {(1, 0): np.lib.format.read_array_header_1_0,
                  (2, 0): np.lib.format.read_array_header_2_0}.get(version)
        if reader is None:
            raise ValueError(f"an .npy member of format version {version}, not 1.0 or 2.0")
        shape, fortran, dtype = reader(f, max_header_size=10000)
        return shape, dtype, fortran, f.tell()

    def read(self, name: str, max_bytes: int | None = None) -> np.ndarray:
        """Array ``name``, after its header says it holds numbers, booleans or text of at most
        ``max_bytes`` (default: the archive's size bound) and its member is exactly that
        long."""
        info = self._member(name)
        try:
            with self._zip.open(info) as f:
                shape, dtype, fortran, offset = self._read_header(f)
                if dtype.hasobject or dtype.kind not in "biufcSU":
                    raise FileError(f"{self.path}: array {name!r} holds {dtype} values, not "
                                    "numbers or text")
                nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
                bound = max_bytes if max_bytes is not None else info.file_size
                if nbytes > bound:
                    raise FileError(f"{self.path}: array {name!r} of shape {shape} would take "
                                    f"{size_bytes(nbytes)}; at most {size_bytes(bound)} are "
                                    "read")
                if info.file_size != offset + nbytes:
                    raise FileError(f"{self.path}: array {name!r} is truncated or padded (its "
                                    f"header says {shape} {dtype}, its member holds "
                                    f"{info.file_size - offset} bytes of data)")
                data = f.read(nbytes)
        except FileError:
            raise
        except _DAMAGE as exc:
            raise self.damaged(exc) from None
        array = np.frombuffer(data, dtype=dtype).copy()
        return array.reshape(shape, order="F" if fortran else "C")

    def close(self) -> None:
        self._zip.close()
        self._file.close()

    def __enter__(self) -> NpzArchive:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
