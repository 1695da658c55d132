"""`rhmpc robots`, `--help`, `--version`, and that the shipped URDF is found."""

import json
import subprocess
import sys

import pytest

from rhmpc import __version__
from rhmpc.cli import main


def test_version_and_help(capsys):
    for argv in (["--version"], ["--help"]):
        try:
            main(argv)
        except SystemExit as exc:
            assert exc.code == 0
    out = capsys.readouterr().out
    assert f"rhmpc {__version__}" in out
    assert "robots" in out


@pytest.mark.slow
def test_robots_table_and_json(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    for name in ("phantom", "finger_edu", "ur5"):
        assert name in out
    assert main(["robots", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    phantom = next(r for r in rows if r["name"] == "phantom")
    assert phantom["dof"] == 3
    assert phantom["jacobian_condition"] < 5


@pytest.mark.slow
def test_console_script_runs_in_a_subprocess():
    out = subprocess.run(
        [sys.executable, "-m", "rhmpc.cli", "robots"], capture_output=True, text=True, check=True
    ).stdout
    assert "phantom" in out
