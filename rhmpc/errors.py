"""Exceptions shared by the application layer, and how the command line shows warnings."""

from __future__ import annotations

import contextlib
import sys
import warnings
from collections.abc import Iterator


class UsageError(ValueError):
    """Bad command-line input or a malformed input file; the CLI prints it on one line, exit 2."""


@contextlib.contextmanager
def one_line_warnings(prefix: str) -> Iterator[None]:
    """Inside, a warning meant for users (a ``UserWarning``, such as a recording's
    ``RecordingWarning``) is printed on one line of stderr, ``PREFIX: warning: MESSAGE``;
    other warnings keep Python's format (file, line and source). The filters are unchanged:
    a warning repeated from the same place is printed once."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        stream = sys.stderr if file is None else file
        if issubclass(category, UserWarning):
            text = " ".join(str(message).split())  # one line, whatever the message holds
            stream.write(f"{prefix}: warning: {text}\n")
        else:
            stream.write(warnings.formatwarning(message, category, filename, lineno, line))

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield
