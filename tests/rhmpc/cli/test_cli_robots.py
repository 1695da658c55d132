"""`rhmpc robots`, `--help`, `--version`, that the shipped URDF is found, and the command's BLAS
threads."""

import json
import os
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


def test_a_robot_file_wherever_a_robot_name_goes(tmp_path, capsys):
    """`robots --robot FILE` shows the robot of a file; a bad one stops `simulate` and `export`
    with one line naming the key, before anything runs."""
    from rhmpc.robots.registry import urdf_path

    text = open(urdf_path("phantom.toml")).read()
    (tmp_path / "phantom_premium_1_5a.urdf").write_text(
        open(urdf_path("phantom_premium_1_5a.urdf")).read())
    (tmp_path / "mine.toml").write_text(text.replace('name = "phantom"', 'name = "mine"'))
    assert main(["robots", "--robot", str(tmp_path / "mine.toml"), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert row["name"] == "mine" and row["q0_deg"] == [0.0, 0.0, 90.0]
    (tmp_path / "bad.toml").write_text(text.replace('"elbow"]', '"elbow2"]'))
    for argv in (["simulate", "--duration", "1"], ["export", str(tmp_path / "out")]):
        assert main([*argv, "--robot", str(tmp_path / "bad.toml")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "joints: no joint 'elbow2'" in err[0], err


def test_the_command_runs_one_blas_thread_unless_the_environment_says(monkeypatch) -> None:
    """``OPENBLAS_NUM_THREADS`` is 1 for the command and its workers, and a value the user set
    stays."""
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    assert main(["robots"]) == 0
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")
    assert main(["robots"]) == 0
    assert os.environ["OPENBLAS_NUM_THREADS"] == "4"
