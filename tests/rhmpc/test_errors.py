"""rhmpc.errors: a warning meant for users is one line on the command line."""

from __future__ import annotations

import subprocess
import sys
import warnings

import pytest

from rhmpc.cli import main
from rhmpc.errors import MAX_MESSAGE, one_line, one_line_warnings


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


def test_a_long_message_keeps_its_start_and_its_end() -> None:
    short = "header columns t,x,y\nare not t,x,y,z"
    assert one_line(short) == "header columns t,x,y are not t,x,y,z"
    long = "header columns " + ",".join(f"c{i}" for i in range(10**5)) + " are not t,x,y,z"
    text = one_line(long)
    assert MAX_MESSAGE <= len(text) <= MAX_MESSAGE + 60
    assert text.startswith("header columns c0,c1,") and text.endswith("c99999 are not t,x,y,z")
    left_out = int(text.split(" … (")[1].split(" characters")[0])
    assert left_out == len(long) - MAX_MESSAGE


def test_the_command_line_cuts_a_message_of_100_000_columns(tmp_path, capsys) -> None:
    """A CSV of 10⁵ columns: the header repeated back is cut to one readable line."""
    path = tmp_path / "wide.csv"
    path.write_text(",".join(["t", *(f"c{i}" for i in range(10**5))]) + "\n"
                    + ",".join(["0", *("1" for _ in range(10**5))]) + "\n")
    assert main(["data", "show", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and len(err) < MAX_MESSAGE + 100, len(err)
    assert "characters left out" in err and "wide.csv" in err


def test_help_loads_no_run_stack() -> None:
    """``rhmpc sil --help`` (``simulate``'s run options among its own) loads neither the run's
    assembly, nor the loop, nor the recordings' readers."""
    code = ("import contextlib, io, sys\nfrom rhmpc.cli import main\n"
            "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
            "    main(['sil', '--help'])\n"
            "print(' '.join(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    loaded = [m for m in ("rhmpc.experiment.assembly", "rhmpc.sim.loop.closed_loop",
                          "rhmpc.sim.recordings", "rhmpc.control", "scipy", "pinocchio")
              if m in out]
    assert not loaded, loaded
