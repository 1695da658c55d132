"""`rhmpc sil` end to end: every process runs and ends; Ctrl-C and SIGTERM stop them all.

Latencies and deadline misses depend on the host's load: they are reported, never asserted
here. What is asserted: the run's ticks, the messages' flow, a score of the same order as the
in-process simulation's, and that no process is left.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rhmpc.cli import main
from rhmpc.compiled import compiler

REPO = Path(__file__).resolve().parents[3]
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("cmake") is None or compiler() is None,
                       reason="cmake or a C compiler missing"),
    pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc"),
]
SIL = ["sil", "--scenario", "fixed-a2-top", "--predictor", "ekf", "--priority", "10"]


def children(pid: int) -> list[int]:
    """The live processes whose parent is ``pid``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def test_every_process_runs_and_ends(capsys):
    """3 s of the EKF (a predictor the controller does not run itself) in its own process:
    its forecasts serve the controller, the robot answers every tick, and the score at the
    measured instants is of the in-process run's order."""
    before = set(children(os.getpid()))  # others' (a resource tracker of earlier tests)
    assert main([*SIL, "--duration", "3", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["ticks"] == 6000 and report["predictor"] == "ekf"
    for key in ("deadline_misses", "wakeup_latency_us", "host_wakeup_latency_us",
                "sensor_to_torque_ms", "packets", "rms_error_mm", "in_process_rms_error_mm"):
        assert key in report
    assert report["points_served_ticks"]["external"] > 0
    assert report["packets"]["forecast_cp"]["received"] > 0
    assert report["packets"]["servo_jf"]["received"] > 0
    assert 0 < report["rms_error_mm"] < 5 * report["in_process_rms_error_mm"]
    assert report["forecast_fallback"] == "the controller's own generalized RLS"
    assert set(children(os.getpid())) - before == set()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_stop_signal_ends_every_process(sig):
    code = ("import signal, sys\nsignal.signal(signal.SIGINT, signal.default_int_handler)\n"
            "from rhmpc.cli import main\nsys.exit(main(sys.argv[1:]))")
    proc = subprocess.Popen([sys.executable, "-c", code, *SIL, "--duration", "60"], cwd=REPO,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        for line in proc.stderr:
            if "in real time" in line:
                break
        time.sleep(3.0)  # the processes are up
        assert len(children(proc.pid)) >= 5
        proc.send_signal(sig)
        assert proc.wait(timeout=60) in (130, -sig, 128 + sig)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            try:
                os.killpg(proc.pid, 0)  # any process of its group still there?
            except ProcessLookupError:
                break
            time.sleep(0.1)
        else:
            pytest.fail("processes of the run are left after the stop")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
