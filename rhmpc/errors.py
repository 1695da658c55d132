"""Exceptions shared by the application layer."""


class UsageError(ValueError):
    """Bad command-line input or a malformed input file; the CLI prints it on one line, exit 2."""
