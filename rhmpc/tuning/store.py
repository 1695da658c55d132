"""The results file of a sweep: JSON lines, appended atomically, read tolerantly.

One line per finished evaluation (see :func:`rhmpc.tuning.record_for`). Each line is written with
a single ``write`` on a file opened ``O_APPEND``, then flushed to disk (``fsync``), so a crash
leaves at most a truncated last line; readers skip lines that are not complete JSON objects. One
writer at a time is enforced with an advisory ``flock``.
"""

from __future__ import annotations

import fcntl
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from rhmpc.errors import UsageError


@dataclass
class ResultsFile:
    """What a results file holds: the complete records, and how many lines were unreadable.

    Attributes
    ----------
    records : list[dict]
        Every complete record, in file order.
    bad_lines : int
        Lines that are not a JSON object with a ``key`` (e.g. a truncated last line).
    """

    records: list[dict] = field(default_factory=list)
    bad_lines: int = 0

    def latest(self) -> dict[str, dict]:
        """The last record of each evaluation key (an ``ok`` one wins over failures)."""
        out: dict[str, dict] = {}
        for r in self.records:
            prev = out.get(r["key"])
            if prev is None or r.get("status") == "ok" or prev.get("status") != "ok":
                out[r["key"]] = r
        return out


def read_results(path: str | Path) -> ResultsFile:
    """Read a results file; a missing file is empty, malformed lines are counted and skipped."""
    path = Path(path)
    out = ResultsFile()
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        return out
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror}") from None
    for line in raw.split(b"\n"):
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            out.bad_lines += 1
            continue
        if not isinstance(record, dict) or "key" not in record:
            out.bad_lines += 1
            continue
        out.records.append(record)
    return out


def check_writable(path: str | Path, option: str) -> None:
    """Refuse an output file that cannot be written, before any run starts.

    Parameters
    ----------
    path : str or Path
        The file to be written later.
    option : str
        The option that named it (``--out``), for the message.

    Raises
    ------
    UsageError
        Its folder is missing or not writable, or the path is a folder.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise UsageError(f"{option} {path}: is a folder; give a file name")
    if not folder.is_dir():
        raise UsageError(f"{option} {path}: no folder {folder}")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise UsageError(f"{option} {path}: not writable")


class ResultsWriter:
    """Appends records to a results file, one durable line each; a context manager.

    Parameters
    ----------
    path : str | Path
        The JSON-lines file (created if missing, parent directories included).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._fd: int | None = None

    def __enter__(self) -> ResultsWriter:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> None:
        if self.path.parent and not self.path.parent.exists():
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        except OSError as exc:
            raise UsageError(f"{self.path}: cannot open for appending: {exc.strerror}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise UsageError(f"{self.path}: another `rhmpc tune` is writing this results "
                             "file") from None
        self._fd = fd
        # A crash may have left a truncated last line: start on a fresh line.
        size = os.fstat(fd).st_size
        if size:
            with open(self.path, "rb") as f:
                f.seek(size - 1)
                if f.read(1) != b"\n":
                    self._write(b"\n")

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # releases the lock
            self._fd = None

    def append(self, record: dict) -> None:
        """Write ``record`` as one line and flush it to disk."""
        if self._fd is None:
            raise RuntimeError("ResultsWriter is not open")
        line = json.dumps(record, separators=(",", ":"), allow_nan=True) + "\n"
        self._write(line.encode())

    def _write(self, data: bytes) -> None:
        assert self._fd is not None
        view = memoryview(data)
        while view:  # a regular file takes it in one write unless the disk is full
            n = os.write(self._fd, view)
            view = view[n:]
        os.fsync(self._fd)
