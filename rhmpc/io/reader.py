"""The one way in: every file rhmpc reads is opened by :func:`open_input`.

A file is read only when

- it is a regular file: a folder, a named pipe (FIFO), a device or a socket is refused before
  anything is read from it, so that nothing blocks (a FIFO with no writer) or streams without
  end (``/dev/zero``);
- it is no larger than the bound of its kind (:data:`rhmpc.io.limits.FILE_BYTES`), checked
  on the open descriptor, and reading stops one byte past the bound should it grow meanwhile;
- structured text is no deeper than :data:`MAX_DEPTH` levels of brackets, checked by a scan of
  the text before the parser (a recursive one) sees it, and again on what it returns.

Every error is a :class:`FileError` whose message starts with the file's name and fits on one
line. Inside :func:`tracking_inputs` (a command's run) every file read is remembered, so that
the writer (:mod:`rhmpc.io.writer`) never replaces one of the run's inputs.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import stat
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from rhmpc.io.limits import FILE_BYTES, size_bytes

__all__ = ["MAX_DEPTH", "FileError", "check_depth", "inputs_read", "json_loads", "open_input",
           "read_bytes", "read_json", "read_text", "read_toml", "text_depth", "tracking_inputs"]

#: The deepest nesting of arrays and tables that a TOML or JSON input may hold [levels]. A
#: run's settings nest three levels (a section's table of a list); 64 leaves room for any
#: hand-written file and stays far below Python's recursion limit (1000 frames).
MAX_DEPTH = 64

#: What each kind of file that is not a regular one is called in a message.
_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe (FIFO)"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISSOCK, "a socket"))

_session: dict[tuple[int, int], str] | None = None


class FileError(ValueError):
    """A file cannot be read or written as asked; the message starts with its name."""


@contextlib.contextmanager
def tracking_inputs() -> Iterator[None]:
    """Inside, every file :func:`open_input` opens is an input of the run
    (:func:`inputs_read`); the writer refuses to replace one."""
    global _session
    outer, _session = _session, {}
    try:
        yield
    finally:
        _session = outer


def inputs_read() -> dict[tuple[int, int], str]:
    """(device, inode) → name of every file read inside :func:`tracking_inputs` (empty
    outside)."""
    return dict(_session or {})


def _refuse_kind(path: Path, mode: int) -> None:
    if stat.S_ISREG(mode):
        return
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    raise FileError(f"{path}: {kind}, not a regular file; give a file")


def _os_error(path: Path, exc: OSError, verb: str = "read") -> FileError:
    if isinstance(exc, FileNotFoundError):
        return FileError(f"{path}: no such file")
    return FileError(f"{path}: cannot {verb}: {exc.strerror or exc}")


def open_input(path: str | Path, kind: str = "file", limit: int | None = None, *,
               track: bool = True) -> IO[bytes]:
    """``path`` opened for reading in binary, checked (module docstring).

    Parameters
    ----------
    path : str or Path
        The file.
    kind : str
        Its kind, a key of :data:`rhmpc.io.limits.FILE_BYTES` (``"config"``, ``"recording"``,
        ``"model"``, …): its largest size, and its name in the message.
    limit : int, optional
        The largest size [B], instead of the kind's.
    track : bool
        Whether the file is an input of the run (:func:`tracking_inputs`); False for rhmpc's
        own files (its build cache), which it rewrites.

    Raises
    ------
    FileError
        Missing, not a regular file, unreadable, or larger than the bound.
    """
    path = Path(path)
    limit = FILE_BYTES[kind] if limit is None else limit
    try:
        _refuse_kind(path, os.stat(path).st_mode)  # a FIFO is refused before it is opened
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise _os_error(path, exc) from None
    try:
        info = os.fstat(fd)
        _refuse_kind(path, info.st_mode)  # what was opened, should the path have changed
        if info.st_size > limit:
            raise FileError(f"{path}: {size_bytes(info.st_size)}, larger than a {kind} may be "
                            f"({size_bytes(limit)})")
        os.set_blocking(fd, True)
        if _session is not None and track:
            _session[(info.st_dev, info.st_ino)] = str(path)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: str | Path, kind: str = "file", limit: int | None = None, *,
               track: bool = True) -> bytes:
    """The whole of ``path`` (:func:`open_input`), at most its bound."""
    limit = FILE_BYTES[kind] if limit is None else limit
    with open_input(path, kind, limit, track=track) as f:
        try:
            data = f.read(limit + 1)
        except OSError as exc:
            raise _os_error(Path(path), exc) from None
    if len(data) > limit:
        raise FileError(f"{path}: grew past the {size_bytes(limit)} a {kind} may be while it "
                        "was read")
    return data


def read_text(path: str | Path, kind: str = "file", limit: int | None = None,
              encoding: str = "utf-8-sig") -> str:
    """``path`` as text (UTF-8, a byte-order mark dropped); bytes that are not text are a
    :class:`FileError` ("not a text file")."""
    try:
        return read_bytes(path, kind, limit).decode(encoding)
    except UnicodeDecodeError as exc:
        raise FileError(f"{path}: not a text file ({exc.reason} at byte {exc.start})") from None


#: What the depth scan stops at: a quote (three, or one), a comment, a bracket.
_TOKEN = re.compile(r'"""|' + r"'''|" + r"""["'#\[\]{}]""")
#: Where each kind of string ends: its closing quote unescaped (basic and multi-line basic
#: strings take backslash escapes, literal ones none), or a one-line string's line end.
_STRING_END = {
    '"': re.compile(r'(?:[^"\\\n]|\\.)*(?:"|\n|$)', re.S),
    "'": re.compile(r"[^'\n]*(?:'|\n|$)"),
    '"""': re.compile(r'(?:[^\\]|\\.)*?(?:"""|$)', re.S),
    "'''": re.compile(r".*?(?:'''|$)", re.S),
}


def text_depth(text: str) -> int:
    """The deepest nesting of ``[`` and ``{`` in TOML or JSON ``text``, outside its strings and
    comments (one pass, no recursion)."""
    depth = deepest = pos = 0
    while (m := _TOKEN.search(text, pos)) is not None:
        token, pos = m.group(), m.end()
        if token in _STRING_END:
            pos = _STRING_END[token].match(text, pos).end()
        elif token == "#":
            end = text.find("\n", pos)
            pos = len(text) if end < 0 else end
        elif token in "[{":
            depth += 1
            deepest = max(deepest, depth)
        else:
            depth = max(0, depth - 1)
    return deepest


def check_depth(value: Any, where: str, limit: int = MAX_DEPTH) -> None:
    """Raise :class:`FileError` when ``value`` (dicts and lists) nests deeper than ``limit``
    (an iterative walk: dotted TOML keys nest without brackets)."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        children = item.values() if isinstance(item, dict) else item \
            if isinstance(item, list) else ()
        for child in children:
            if isinstance(child, dict | list):
                if depth + 1 > limit:
                    raise FileError(f"{where}: nested deeper than {limit} levels")
                stack.append((child, depth + 1))


def _check_text_depth(text: str, where: str) -> None:
    depth = text_depth(text)
    if depth > MAX_DEPTH:
        raise FileError(f"{where}: nested {depth} levels deep; at most {MAX_DEPTH} are read")


def read_toml(path: str | Path, kind: str = "config") -> dict[str, Any]:
    """A TOML file as a ``dict``, its size and depth bounded before it is parsed; every
    problem is a :class:`FileError` naming the file (and, for TOML's own errors, the line)."""
    text = read_text(path, kind, encoding="utf-8")
    _check_text_depth(text, str(path))
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FileError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:  # pragma: no cover - the scan above bounds the depth
        raise FileError(f"{path}: nested too deep to parse") from None
    check_depth(data, str(path))
    return data


def json_loads(text: str | bytes, where: str) -> Any:
    """JSON ``text``, its depth bounded before it is parsed; a :class:`FileError` names
    ``where``."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FileError(f"{where}: not UTF-8 text ({exc.reason})") from None
    _check_text_depth(text, where)
    try:
        return json.loads(text)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise FileError(f"{where}: not valid JSON ({exc})") from None


def read_json(path: str | Path, kind: str = "file", *, track: bool = True) -> Any:
    """A JSON file, bounded in size and depth (:func:`json_loads`)."""
    return json_loads(read_bytes(path, kind, track=track), str(path))
