"""The run's key: 32 random bytes, given to a process as a file only its user may read.

A key file holds 64 hexadecimal digits (a newline after them is allowed), as
``openssl rand -hex 32`` writes them. A regular file must belong to the user reading it and
give no permission to its group or to others (mode 0600 or 0400), as ssh asks of a private
key; a key given as an inherited descriptor (``/dev/fd/N``, a pipe) shows nowhere on disk.
``rhmpc sil`` makes a new key for each run and hands it to its programs that way; a lab's own
tracker, predictor or drivers read the same kind of file (``--key-file``).
"""

from __future__ import annotations

import os
import secrets
import stat
from pathlib import Path

__all__ = ["KEY_BYTES", "KeyFileError", "new_key", "read_key", "write_key"]

#: Bytes of a key (HMAC-SHA-256's block is 64: a 32-byte key is used as it is).
KEY_BYTES = 32


class KeyFileError(ValueError):
    """A key file that cannot be used (its path and why, on one line)."""


def new_key() -> bytes:
    """A fresh key from the operating system's random source (:func:`secrets.token_bytes`)."""
    return secrets.token_bytes(KEY_BYTES)


def _parse(text: bytes, where: str) -> bytes:
    digits = text.strip()
    if len(digits) != 2 * KEY_BYTES:
        raise KeyFileError(f"{where}: a key file holds {2 * KEY_BYTES} hexadecimal digits, "
                        f"found {len(digits)} characters")
    try:
        return bytes.fromhex(digits.decode("ascii"))
    except (UnicodeDecodeError, ValueError):
        raise KeyFileError(f"{where}: a key file holds {2 * KEY_BYTES} hexadecimal digits "
                        "(0-9, a-f)") from None


def read_key(path: str | Path) -> bytes:
    """The key in ``path``: a file of the caller's own with mode 0600 or 0400 (not a link), or
    an inherited descriptor (``/dev/fd/N``, read once and closed). :class:`KeyFileError` names
    the file and the problem."""
    where = str(path)
    inherited = where.removeprefix("/dev/fd/")
    try:
        fd = int(inherited) if inherited != where and inherited.isdigit() else \
            os.open(where, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as exc:
        raise KeyFileError(f"{where}: cannot open the key file ({exc.strerror})") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISREG(info.st_mode):
            if info.st_uid != os.geteuid():
                raise KeyFileError(f"{where}: the key file belongs to another user")
            if info.st_mode & 0o077:
                raise KeyFileError(f"{where}: the key file may be read by others (mode "
                                f"{stat.S_IMODE(info.st_mode):04o}): chmod 600 {where}")
        elif not stat.S_ISFIFO(info.st_mode):
            raise KeyFileError(f"{where}: not a regular file or a pipe")
        text = os.read(fd, 4 * KEY_BYTES)
    finally:
        os.close(fd)
    return _parse(text, where)


def write_key(fd: int, key: bytes) -> None:
    """Write ``key`` as hexadecimal digits to the descriptor ``fd`` (a pipe's write end, or a
    file opened with mode 0600) and close it."""
    try:
        os.write(fd, key.hex().encode("ascii") + b"\n")
    finally:
        os.close(fd)
