"""rhmpc.errors: a warning meant for users is one line on the command line."""

from __future__ import annotations

import warnings

import pytest

from rhmpc.errors import one_line_warnings


class _Notice(UserWarning):
    pass


def test_user_warnings_are_one_line_others_keep_their_place(
        capsys: pytest.CaptureFixture[str]) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        with one_line_warnings("rhmpc data"):
            warnings.warn("rec.csv: spans 5000 mm;\nread in m", _Notice, stacklevel=1)
            warnings.warn("overflow", RuntimeWarning, stacklevel=1)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "rhmpc data: warning: rec.csv: spans 5000 mm; read in m"
    assert "test_errors.py" in err[1] and "RuntimeWarning: overflow" in err[1]
    assert warnings.showwarning.__name__ != "show"  # restored on exit
