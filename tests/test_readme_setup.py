"""The README's set-up and commands as a new user meets them: an editable install whose edits show
in the next run, continuous integration running the README's test command verbatim, the
documentation built with warnings as errors, the tables each command names, the citations."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rhmpc.cli import build_parser
from rhmpc.experiment import RunConfig
from rhmpc.experiment.presets import PRESETS
from rhmpc.experiment.tables import to_dict
from rhmpc.paper.tables import paper_table

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def bash_lines() -> list[str]:
    """The commands of the README's fenced bash blocks, comments left out."""
    blocks = re.findall(r"^```bash\n(.*?)^```", README, re.S | re.M)
    return [line.strip() for block in blocks for line in block.splitlines()
            if line.strip() and not line.strip().startswith("#")]


def setup_line() -> str:
    """The set-up command: the first bash line that makes the environment."""
    return next(line for line in bash_lines() if "venv" in line)


def test_the_setup_is_an_editable_install() -> None:
    assert re.search(r"pip install (-e|--editable) ", setup_line()), setup_line()


def test_ci_runs_the_readmes_test_command_verbatim() -> None:
    test_command = next(line for line in bash_lines() if "pytest" in line)
    assert "pip install -e" in test_command
    assert test_command in (ROOT / ".ci" / "run").read_text().splitlines()


def pip_installs() -> list[str]:
    """The README's ``pip install`` commands, each from ``pip`` to its end or its ``&&``."""
    return [m.group(0) for line in bash_lines()
            for m in re.finditer(r"\.venv/bin/pip install [^&]*[^&\s]", line)]


def test_every_install_keeps_the_checkout_editable() -> None:
    """Each install of the README is editable, the docs extra's too: ``pip install ".[docs]"``
    would replace the editable install with a copy of the checkout."""
    installs = pip_installs()
    assert len(installs) >= 3 and any("[docs]" in i for i in installs), installs
    for command in installs:
        assert re.search(r"pip install (-e|--editable) ", command), command


def test_ci_installs_and_builds_the_docs_as_the_readme_says() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    docs = next(i for i in pip_installs() if "[docs]" in i)
    assert docs in ci.splitlines()
    apt = next(line for line in bash_lines() if "apt-get install" in line)
    for package in apt.split("apt-get install", 1)[1].split():  # CI installs what is missing
        assert f"missing+=({package})" in ci, package


def test_the_readme_names_every_system_tool_the_tests_use() -> None:
    """What the tests look up on the machine, and the Debian package of each."""
    apt = next(line for line in bash_lines() if "apt-get install" in line)
    for tool, package in (("C compiler", "build-essential"), ("cmake", "cmake"),
                          ("libcrypto", "libssl-dev"), ("Chromium", "chromium")):
        assert tool in README and package in apt.split(), (tool, package)
    prose = " ".join(README.split())
    assert re.search(r"On 2 cores .*? the whole suite takes about \d+ minutes", prose)
    assert re.search(r'`-m "not slow"` runs its quick part, (about \d+ minutes|under a minute)',
                     prose)


def test_the_docs_command_turns_warnings_into_errors() -> None:
    sphinx = [line for line in bash_lines() if "sphinx" in line]
    assert sphinx and all(" -W " in line for line in sphinx)


def test_every_cited_author_has_initials() -> None:
    citing = README.split("## Citing", 1)[1].split("\n## ", 1)[0]
    entries = re.findall(r"^- (.*?)(?=^- |^\s*$)", citing, re.M | re.S)
    assert len(entries) == 4
    for entry in entries:
        authors = " ".join(entry.split('"', 1)[0].split()).rstrip(", ").split(", ")
        for author in authors:
            assert re.fullmatch(r"(\w\. )+[\w-]+", author), f"no initials: {author!r}"


def test_help_and_readme_name_the_tables_each_preset_is_set_beside() -> None:
    """``rhmpc --help`` names Tables I–III; each README line `compare --preset P --paper`
    names the tables that ``--paper`` sets that preset's runs beside."""
    assert "Tables I–III" in build_parser().format_help()
    lines = re.findall(r"^rhmpc compare --preset ([\w-]+) --paper\s+# (.*)$", README, re.M)
    assert {preset for preset, _ in lines} == {"tuna2013", "tuna2013-hardware"}
    for preset, comment in lines:
        plant = to_dict(RunConfig().replace(**PRESETS[preset]).plant)
        docs = [{"predictor": "exact", "scenario": "fixed-a2-top", "seed": 0,
                 "rms_error_mm": 0.1, "max_error_mm": 0.5, "rms_effort_mNm": 20.0,
                 "settings": {"plant": plant}}]
        header = paper_table(docs, ["exact"], ["fixed-a2-top"]).splitlines()[0]
        tables = re.search(r"set beside (Tables? [IV–]+)", header).group(1)
        assert re.search(rf"\b{tables}\b", comment), (preset, comment, tables)


EDIT = '''

_unedited_predict = Predictor.predict


def _shifted_predict(self, *args, **kwargs):  # an edit a researcher might make
    import numpy as _np
    return _np.asarray(_unedited_predict(self, *args, **kwargs)) + 0.001


Predictor.predict = _shifted_predict
'''


def _rms(clone: Path, env: dict) -> float:
    out = subprocess.run([str(clone / ".venv" / "bin" / "rhmpc"), "simulate", "--predictor",
                          "generalized", "--duration", "3", "--seed", "1", "--json"],
                         cwd=clone, env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)["rms_error_mm"]


def _pip(clone: Path, env: dict, command: str) -> None:
    """A README ``pip install`` command in the copy's environment, offline: its own arguments,
    with the dependencies from this environment (``--no-deps``) and the build backend too
    (``--no-build-isolation``)."""
    args = shlex.split(command.split("pip install", 1)[1])
    done = subprocess.run([str(clone / ".venv" / "bin" / "python"), "-m", "pip", "install", "-q",
                           "--no-deps", "--no-build-isolation", "--no-index", *args], cwd=clone,
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.mark.slow
def test_an_edit_shows_in_the_next_run_after_the_readmes_setup(tmp_path: Path) -> None:
    """A copy of the checkout, the README's install and then its docs step's install (their
    pip arguments, offline: the dependencies come from this environment), an edit that shifts
    every forecast by 1 mm, and the next ``rhmpc simulate`` of the copy's environment."""
    for backend in ("setuptools", "wheel"):  # the build, without a network
        if importlib.util.find_spec(backend) is None:
            pytest.skip(f"pip cannot build the project offline here: no {backend} (the test "
                        "extra brings it)")
    clone = tmp_path / "clone"
    shutil.copytree(ROOT, clone, ignore=shutil.ignore_patterns(
        ".venv", ".git", "_build", "build", "*.egg-info", "__pycache__", ".pytest_cache"))
    # without pip (and the old setuptools it brings): this environment's pip and setuptools,
    # with the dependencies, come in through a path file
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(clone / ".venv")],
                   check=True)
    site = next((clone / ".venv" / "lib").glob("python*/site-packages"))
    # this environment's import paths (its site-packages and those its path files add), not
    # its own editable install of the project (a finder, not a path) nor the checkout
    ours = [p for p in sys.path if p.startswith(sys.prefix) and Path(p).is_dir()]
    (site / "dependencies.pth").write_text("\n".join(ours) + "\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    setup = re.search(r"\.venv/bin/pip install .*?(?= &&|$)", setup_line()).group(0)
    docs = next(i for i in pip_installs() if "[docs]" in i)
    _pip(clone, env, setup)
    before = _rms(clone, env)
    _pip(clone, env, docs)  # the docs step: the install stays editable
    with (clone / "predictors" / "base.py").open("a") as f:
        f.write(EDIT)
    after = _rms(clone, env)
    assert abs(after - before) >= 0.3, (before, after)
