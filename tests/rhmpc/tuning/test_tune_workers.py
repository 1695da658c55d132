"""Worker processes die with their parent: a sweep killed with SIGKILL leaves nothing behind,
and Ctrl-C stops the workers at once.

The fast tests start a pool of :func:`rhmpc.tuning.workers.process_pool` in a subprocess with a
stand-in job that sleeps; the slow one runs a tiny ``rhmpc tune`` and kills it.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="reads the process table in /proc")

#: A subprocess that starts two workers (each writes its pid to a file, then sleeps) and waits;
#: on Ctrl-C it stops them as the runners do.
SCRIPT = """
import signal, sys, time
# Ctrl-C as a terminal delivers it, even where the test runs in a background job (a shell
# without job control starts those with SIGINT ignored, and a child inherits that)
signal.signal(signal.SIGINT, signal.default_int_handler)
from pathlib import Path
from rhmpc.tuning.workers import process_pool, stop_executor
import standin

out = Path(sys.argv[1])
pool = process_pool(2, start_method=sys.argv[2])
futures = [pool.submit(standin.mark_and_sleep, str(out), i) for i in range(2)]
try:
    time.sleep(120)
except KeyboardInterrupt:
    stop_executor(pool, futures)
    sys.exit(130)
"""

STANDIN = """
import os, time
from pathlib import Path

def mark_and_sleep(folder, i):
    Path(folder, f"worker{i}.pid").write_text(str(os.getpid()))
    time.sleep(120)
"""


def _children(pid: int) -> list[int]:
    """Every process whose parent is ``pid`` (workers and the resource tracker)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rpartition(")")[2].split()[1]) == pid:
                out.append(int(entry.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except OSError:
        return False
    return state != "Z"


def _until(condition: Callable[[], bool], timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def _kill_all(pids: list[int]) -> None:
    for pid in pids:
        if _alive(pid):
            os.kill(pid, signal.SIGKILL)


def _start(tmp_path: Path, start_method: str) -> tuple[subprocess.Popen, list[int]]:
    """The subprocess, once both workers run their job; its children."""
    (tmp_path / "standin.py").write_text(textwrap.dedent(STANDIN))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(REPO)])}
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT, str(tmp_path), start_method],
                            env=env, cwd=tmp_path, start_new_session=True)
    marked = _until(lambda: len(list(tmp_path.glob("worker*.pid"))) == 2, 30.0)
    children = _children(proc.pid)
    if not marked:
        proc.kill()
        _kill_all(children)
        pytest.fail("the workers did not start within 30 s")
    return proc, children


@pytest.mark.parametrize("start_method", ["spawn", "fork"])
def test_workers_die_when_the_parent_is_killed(tmp_path: Path, start_method: str) -> None:
    proc, children = _start(tmp_path, start_method)
    workers = [int(p.read_text()) for p in tmp_path.glob("worker*.pid")]
    assert set(workers) <= set(children)
    try:
        proc.kill()  # SIGKILL: no handler runs in the parent
        proc.wait()
        assert _until(lambda: not any(map(_alive, children)), 5.0), (
            f"still alive 5 s after the parent's SIGKILL: {[p for p in children if _alive(p)]}")
    finally:
        _kill_all(children)


def test_ctrl_c_stops_the_workers_at_once(tmp_path: Path) -> None:
    """Ctrl-C does not wait for the runs in flight (two minutes each here): the parent exits
    with 130 and no worker is left (the bounds only catch a hang, on any machine's load)."""
    proc, children = _start(tmp_path, "fork")
    try:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60) == 130
        assert _until(lambda: not any(map(_alive, children)), 10.0)
    finally:
        proc.kill()
        _kill_all(children)


def test_die_with_parent_exits_when_the_parent_is_already_gone() -> None:
    code = ("import os, sys\nfrom rhmpc.tuning.workers import die_with_parent\n"
            "die_with_parent(os.getppid() + 1_000_000)\nsys.exit(0)")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, timeout=30)
    assert done.returncode == 1


TUNE_SPEC = """
name = "killed"
[base]
predictor = "one-step"
[base.loop]
duration = 60.0
settling = 1.0
[parameters]
"mpc.effort_weight" = [1e-5, 1e-4, 1e-3, 1e-2]
[evaluate]
scenarios = ["fixed-a2-top"]
"""


@pytest.mark.slow
def test_tune_killed_leaves_no_process_and_resumes(tmp_path: Path) -> None:
    spec = tmp_path / "killed.toml"
    spec.write_text(TUNE_SPEC)
    results = tmp_path / "r.jsonl"
    argv = [sys.executable, "-m", "rhmpc.cli", "tune", str(spec), "--results", str(results)]
    proc = subprocess.Popen([*argv, "--jobs", "2", "--quiet"], cwd=REPO, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    children: list[int] = []
    try:
        assert _until(lambda: len(_spawned(proc.pid)) == 2, 60.0), "no workers within 60 s"
        time.sleep(1.0)  # they are past their start-up or in it: both must die
        children = _children(proc.pid)
        proc.kill()
        proc.wait()
        assert _until(lambda: not any(map(_alive, children)), 5.0), (
            f"still alive 5 s after tune's SIGKILL: {[p for p in children if _alive(p)]}")
    finally:
        proc.kill()
        _kill_all(children)
    dry = subprocess.run([*argv, "--dry-run"], cwd=REPO, capture_output=True, text=True,
                         timeout=120)
    counts = re.search(r"done (\d+), failed 0, to run (\d+)", dry.stderr)
    assert dry.returncode == 0 and counts and sum(map(int, counts.groups())) == 4
    assert "unreadable" not in dry.stderr  # nothing lost, nothing half-written


def _spawned(pid: int) -> list[int]:
    """The children of ``pid`` that are multiprocessing spawn workers."""
    out = []
    for child in _children(pid):
        try:
            if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                out.append(child)
        except OSError:
            pass
    return out
