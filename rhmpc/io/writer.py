"""The one way out: every file rhmpc writes is written by :class:`AtomicFile`.

A file is written to a temporary file in the folder of its target, flushed to disk
(``fsync``) and renamed over the target in one step (``os.replace``), so that a reader sees
the previous file or the new one, never a part. On a failure (a full disk, an interruption)
the temporary file is removed and the previous file stays as it was; the error names the
target. Before any of it, :func:`check_output` refuses

- a target that is a symbolic link (a link is never written through) or a folder;
- a target outside the folder it was given in, or reached through a link below that folder
  (``root``: ``rhmpc export DIR`` writes ``DIR/osqp/...`` only if ``DIR/osqp`` is a real
  folder inside ``DIR``);
- a target that is one of the run's inputs: a file named in ``inputs``, or one read through
  :mod:`rhmpc.io.reader` inside :func:`rhmpc.io.reader.tracking_inputs`.

Commands check their outputs before the run (:func:`check_output`); the writer checks again
when it writes.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from rhmpc.io.reader import FileError, inputs_read

__all__ = ["AtomicFile", "atomic_write", "check_output", "file_stem", "make_folder", "save_figure",
           "write_bytes", "write_text"]

_UMASK = os.umask(0)
os.umask(_UMASK)


def _lstat(path: Path) -> os.stat_result | None:
    try:
        return os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        return None


def _is_input(path: Path, info: os.stat_result | None, inputs: Iterable) -> str | None:
    """The input that ``path`` is, by name or by identity (device, inode), or None."""
    for given in inputs:
        given = Path(given)
        try:
            if info is not None and os.path.samefile(given, path):
                return str(given)
        except OSError:
            pass
        if os.path.abspath(given) == os.path.abspath(path):
            return str(given)
    if info is not None:
        return inputs_read().get((info.st_dev, info.st_ino))
    return None


def _inside(path: Path, root: Path) -> None:
    """Refuse ``path`` unless it lies inside ``root`` with no link between them."""
    rel = os.path.relpath(os.path.abspath(path), os.path.abspath(root))
    parts = Path(rel).parts
    if rel == "." or parts[0] == os.pardir or os.path.isabs(rel):
        raise FileError(f"{path}: outside the folder {root} it is written in")
    here = Path(root)
    for part in parts[:-1]:
        here = here / part
        info = _lstat(here)
        if info is not None and stat.S_ISLNK(info.st_mode):
            raise FileError(f"{here}: a symbolic link (to {os.readlink(here)}); rhmpc writes "
                            f"nothing through a link, so not {path}")
        if info is not None and not stat.S_ISDIR(info.st_mode):
            raise FileError(f"{here}: not a folder, so {path} cannot be written")


def check_output(path: str | Path, option: str | None = None, *, root: str | Path | None = None,
                 inputs: Iterable = (), create: bool = False) -> Path:
    """Refuse ``path`` as an output (module docstring) with a :class:`FileError` that names
    it (after ``option``, the option that named it, if given); also when its folder is missing
    (unless ``create``: it will be made, :func:`make_folder`) or not writable. Returns the
    path."""
    path = Path(path)
    name = f"{option} {path}" if option else str(path)
    try:
        if root is not None:
            _inside(path, Path(root))
        info = _lstat(path)
        if info is not None and stat.S_ISLNK(info.st_mode):
            raise FileError(f"{path}: a symbolic link (to {os.readlink(path)}); rhmpc writes "
                            "nothing through a link: remove it or choose another name")
        if info is not None and stat.S_ISDIR(info.st_mode):
            raise FileError(f"{path}: is a folder; give a file name")
        if info is not None and not stat.S_ISREG(info.st_mode):
            raise FileError(f"{path}: not a regular file; give a file name")
        if (source := _is_input(path, info, inputs)) is not None:
            raise FileError(f"{path}: is an input of this run ({source}); rhmpc never "
                            "overwrites its inputs: choose another name")
    except FileError as exc:
        if not option:
            raise
        raise FileError(f"{option} {exc}") from None
    folder = path.parent
    if create and not folder.exists():
        return path
    if not folder.is_dir():
        raise FileError(f"{name}: no such directory {folder.resolve()}")
    if not os.access(folder, os.W_OK | os.X_OK) or (path.exists()
                                                     and not os.access(path, os.W_OK)):
        raise FileError(f"{name}: cannot write there")
    return path


def make_folder(path: str | Path, root: str | Path) -> Path:
    """Create folder ``path`` (and its parents) inside ``root``, refusing links and files in
    the way (:func:`check_output`'s rules)."""
    path = Path(path)
    _inside(path / "x", Path(root))
    info = _lstat(path)
    given = os.path.abspath(path) == os.path.abspath(root)  # the folder given may be a link
    if info is not None and stat.S_ISLNK(info.st_mode) and not given:
        raise FileError(f"{path}: a symbolic link (to {os.readlink(path)}); rhmpc writes "
                        "nothing through a link")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FileError(f"{path}: cannot create the folder: {exc.strerror or exc}") from None
    return path


class AtomicFile:
    """A file being written: a temporary file in the target's folder until :meth:`commit`
    renames it over the target; :meth:`discard` (or an error in ``with``) removes it.

    Parameters
    ----------
    path : str or Path
        The target; checked by :func:`check_output` first.
    mode : str
        ``"wb"`` (default) or ``"w"`` (text, UTF-8, ``newline`` as given).
    root, inputs
        As for :func:`check_output`.
    """

    def __init__(self, path: str | Path, mode: str = "wb", *, root: str | Path | None = None,
                 inputs: Iterable = (), newline: str | None = None) -> None:
        self.path = check_output(path, root=root, inputs=inputs)
        self._root, self._inputs = root, tuple(inputs)
        try:
            fd, temp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".part",
                                        dir=self.path.parent)
        except OSError as exc:
            raise self.error(exc) from None
        self._temp = Path(temp)
        info = _lstat(self.path)
        os.fchmod(fd, stat.S_IMODE(info.st_mode) if info is not None else 0o666 & ~_UMASK)
        kwargs = {} if "b" in mode else {"encoding": "utf-8", "newline": newline}
        self.file: IO = os.fdopen(fd, mode, **kwargs)

    def error(self, exc: BaseException) -> FileError:
        """The error of a failed write: it names the target and says whether a previous
        file is kept."""
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        kept = "; the previous file is kept" if self.path.exists() else ""
        return FileError(f"{self.path}: cannot write: {reason}{kept}")

    def commit(self) -> Path:
        """Flush the file to disk and rename it over the target (checked once more)."""
        try:
            self.file.flush()
            os.fsync(self.file.fileno())
            self.file.close()
            check_output(self.path, root=self._root, inputs=self._inputs)
            os.replace(self._temp, self.path)
        except OSError as exc:
            error = self.error(exc)
            self.discard()
            raise error from None
        except BaseException:
            self.discard()
            raise
        with contextlib.suppress(OSError):  # the rename itself, on disk
            folder = os.open(self.path.parent, os.O_RDONLY)
            try:
                os.fsync(folder)
            finally:
                os.close(folder)
        return self.path

    def discard(self) -> None:
        """Remove the temporary file; the target is untouched."""
        with contextlib.suppress(OSError):
            self.file.close()
        with contextlib.suppress(OSError):
            self._temp.unlink()

    def __enter__(self) -> IO:
        return self.file

    def __exit__(self, kind, exc, tb) -> None:
        if kind is not None:
            self.discard()
            if isinstance(exc, OSError) and not isinstance(exc, FileError):
                raise self.error(exc) from None
            return
        self.commit()


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb", **kwargs) -> Iterator[IO]:
    """``with atomic_write(path) as f: ...``: :class:`AtomicFile` as a context manager (an
    ``OSError`` inside, such as a full disk, becomes a :class:`FileError` naming ``path``)."""
    with AtomicFile(path, mode, **kwargs) as f:
        yield f


def write_bytes(path: str | Path, data: bytes, **kwargs) -> Path:
    """Write ``data`` to ``path`` atomically (:class:`AtomicFile`)."""
    with AtomicFile(path, "wb", **kwargs) as f:
        f.write(data)
    return Path(path)


def write_text(path: str | Path, text: str, **kwargs) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:class:`AtomicFile`)."""
    return write_bytes(path, text.encode("utf-8"), **kwargs)


def file_stem(label: str) -> str:
    """A file name made from ``label`` (a recording's label, say): its characters outside
    letters, digits, ``-``, ``_`` and ``.`` replaced by ``-`` and, when any was, eight hex
    digits of the label's SHA-256 appended, so that two labels never share a name (``x y.csv``
    and ``x-y.csv`` give ``x-y.csv-…`` and ``x-y.csv``)."""
    stem = "".join(c if c.isascii() and (c.isalnum() or c in "-_.") else "-" for c in label)
    stem = stem.lstrip(".") or "-"
    if stem != label:
        stem += "-" + hashlib.sha256(label.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return stem


def save_figure(figure, path: str | Path, **savefig) -> Path:
    """Write a Matplotlib ``figure`` to ``path`` atomically, in the format its suffix names
    (``figure.savefig(file, format=…, **savefig)``)."""
    path = Path(path)
    with AtomicFile(path) as f:
        figure.savefig(f, format=path.suffix.lstrip(".").lower() or None, **savefig)
    return path
