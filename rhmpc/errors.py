"""Exceptions shared by the application layer, and how the command line shows warnings."""

from __future__ import annotations

import contextlib
import sys
import warnings
from collections.abc import Iterator

#: The longest message printed [characters]: about eight lines of a terminal, room for the
#: longest list of valid keys (the MPC's settings); a longer one (a header of 10⁵ columns
#: repeated back) keeps its start and its end.
MAX_MESSAGE = 800
#: Of a message cut short, the characters kept at its end (where the reason often is).
MESSAGE_TAIL = 200


class UsageError(ValueError):
    """Bad command-line input or a malformed input file; the CLI prints it on one line, exit 2."""


def one_line(message: object, limit: int = MAX_MESSAGE) -> str:
    """``message`` on one line (its whitespace collapsed) of at most about ``limit``
    characters: a longer one keeps its start and its last :data:`MESSAGE_TAIL` characters,
    saying how many were left out between."""
    text = " ".join(str(message).split())
    if len(text) <= limit:
        return text
    tail = min(MESSAGE_TAIL, limit // 4)
    head = limit - tail
    return f"{text[:head]} … ({len(text) - head - tail} characters left out) … {text[-tail:]}"


@contextlib.contextmanager
def one_line_warnings(prefix: str) -> Iterator[None]:
    """Inside, a warning meant for users (a ``UserWarning``, such as a recording's
    ``RecordingWarning``) is printed on one line of stderr, ``PREFIX: warning: MESSAGE``;
    other warnings keep Python's format (file, line and source). The filters are unchanged:
    a warning repeated from the same place is printed once."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        stream = sys.stderr if file is None else file
        if issubclass(category, UserWarning):
            stream.write(f"{prefix}: warning: {one_line(message)}\n")
        else:
            stream.write(warnings.formatwarning(message, category, filename, lineno, line))

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield
