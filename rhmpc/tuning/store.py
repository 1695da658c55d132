"""The results file of a sweep: JSON lines, appended atomically, read tolerantly.

One line per finished evaluation (see :func:`rhmpc.tuning.record_for`). Each line is written with
a single ``write`` on a file opened ``O_APPEND``, then flushed to disk (``fsync``), so a crash
leaves at most a truncated last line. The file is read through the one reader
(:func:`rhmpc.io.read_bytes`: a regular file of at most 1 GiB), and a line is a record only if it
is a JSON object with the fields a record has (:func:`is_record`); the others (a line cut short
by a crash, a line edited by hand) are skipped and counted. One writer at a time is enforced
with an advisory ``flock``.
"""

from __future__ import annotations

import fcntl
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from rhmpc import io
from rhmpc.errors import UsageError
from rhmpc.io import FileError

#: The statuses of a record.
STATUSES = ("ok", "failed")
#: Each field every record has, and its type.
RECORD_FIELDS: dict[str, type | tuple[type, ...]] = {
    "key": str, "point": str, "status": str, "parameters": dict, "settings": dict}
#: The longest line that is read as a record [characters]: a record is about 2 kB.
MAX_LINE = 1 << 20


@dataclass
class ResultsFile:
    """What a results file holds: the complete records, and how many lines were unreadable.

    Attributes
    ----------
    records : list[dict]
        Every complete record, in file order.
    bad_lines : int
        Lines that are not records (:func:`is_record`), e.g. a truncated last line.
    first_bad : int or None
        The number of the first of them (from 1).
    """

    records: list[dict] = field(default_factory=list)
    bad_lines: int = 0
    first_bad: int | None = None

    def skipped(self, path: str | Path) -> str | None:
        """What was skipped, for a warning naming ``path``; None if nothing was."""
        if not self.bad_lines:
            return None
        return (f"{path}: skipped {self.bad_lines} line(s) that are not results records "
                f"(the first: line {self.first_bad}), e.g. a line cut short by a crash")

    def latest(self) -> dict[str, dict]:
        """The last record of each evaluation key (an ``ok`` one wins over failures)."""
        out: dict[str, dict] = {}
        for r in self.records:
            prev = out.get(r["key"])
            if prev is None or r.get("status") == "ok" or prev.get("status") != "ok":
                out[r["key"]] = r
        return out


def is_record(record: object) -> bool:
    """Whether ``record`` is a results line: a dict with every field of
    :data:`RECORD_FIELDS` of its type, a status of :data:`STATUSES`, the ``metrics`` (a dict)
    of an ``ok`` one and, if present, an ``objective`` that is a dict."""
    if not isinstance(record, dict):
        return False
    if not all(isinstance(record.get(k), kind) for k, kind in RECORD_FIELDS.items()):
        return False
    if record["status"] not in STATUSES or not isinstance(record.get("objective", {}), dict):
        return False
    return record["status"] != "ok" or isinstance(record.get("metrics"), dict)


def _parse(line: bytes, where: str) -> dict | None:
    if len(line) > MAX_LINE:
        return None
    try:
        record = io.json_loads(line, where)
    except FileError:
        return None
    return record if is_record(record) else None


def read_results(path: str | Path) -> ResultsFile:
    """Read a results file; a missing file is empty, lines that are not records are counted
    and skipped."""
    path = Path(path)
    out = ResultsFile()
    if not os.path.lexists(path):
        return out
    try:
        with io.open_input(path, "results file") as f:
            for number, line in enumerate(f, 1):
                if not line.strip():
                    continue
                record = _parse(line, f"{path}, line {number}")
                if record is None:
                    out.bad_lines += 1
                    out.first_bad = out.first_bad or number
                else:
                    out.records.append(record)
    except FileError as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return out


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
        if self.path.is_symlink():  # never written through a link (rhmpc.io.writer)
            raise UsageError(f"{self.path}: a symbolic link (to {os.readlink(self.path)}); rhmpc "
                             "writes nothing through a link: give the file itself")
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW,
                         0o644)
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
