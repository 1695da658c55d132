"""The C side of the wire: the robot-side client against a Python controller, and the
controller's program against a Python robot, predictor and sensor that lose, reorder and
mangle messages. The counts are asserted, never a latency (the host's load decides those)."""

from __future__ import annotations

import json
import re
import subprocess
import time
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from rhmpc.compiled import compiler
from rhmpc.runtime.wire import Link, run_clock

C = Path(str(files("rhmpc.runtime").joinpath("export")))
needs_cc = pytest.mark.skipif(compiler() is None, reason="no C compiler")
TS = 0.5e-3


def _until_tick(epoch: int, tick: float) -> None:
    while (left := tick * TS - run_clock(epoch)) > 0:
        time.sleep(min(left, 0.01))


@needs_cc
def test_the_robot_side_client_talks_to_a_python_controller(tmp_path):
    """The client's measured_js decode in Python, one per tick; the torques Python sends back
    are applied (or the last one holds when one comes after 0.7 Ts, then late); one for a
    tick already past is counted late."""
    program = tmp_path / "robot_client"
    subprocess.run([compiler(), "-std=c99", "-O2", f"-I{C}", str(C / "robot_client.c"), "-o",
                    str(program), "-lm"], check=True, capture_output=True)
    ticks = 400
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + 300_000_000
    controller, robot = Link(epoch_ns=epoch), Link(epoch_ns=epoch)
    robot_port = robot.port
    robot.close()  # the client binds it
    client = subprocess.Popen([str(program), str(controller.port), str(robot_port), str(epoch),
                               str(ticks)], stdout=subprocess.PIPE, text=True)
    stamps = []
    try:
        while (message := controller.receive(timeout=2.0)) is not None:
            assert message.kind == "measured_js" and message.values.shape == (1, 3)
            stamps.append(message.stamp)
            tick = round(message.stamp / TS)
            if tick == 100:  # a torque for a tick before: late
                controller.send(robot_port, "servo_jf", (tick - 1) * TS, [[9.0, 9.0, 9.0]])
            controller.send(robot_port, "servo_jf", message.stamp, [[0.1, 0.2, 0.3]])
        out = client.communicate(timeout=10)[0]
    finally:
        client.kill()
        controller.close()
    np.testing.assert_allclose(np.diff(stamps), TS)
    applied, held, late = (int(w) for w in re.findall(r"\d+", out))
    assert applied + held == ticks and applied > 0 and 1 <= late <= held + 1, out


@pytest.fixture(scope="module")
def program():
    """The controller's program of the default run (exported and built with CMake)."""
    import shutil

    if shutil.which("cmake") is None or compiler() is None:
        pytest.skip("cmake or a C compiler missing")
    from rhmpc.experiment import RunConfig
    from rhmpc.runtime.build import build_controller

    return build_controller(RunConfig(), 257.0)


@pytest.mark.slow
def test_the_controller_counts_and_survives_bad_traffic(program, tmp_path):
    """0.4 s of ticks: samples with a gap of 2 (lost: missing samples) and one reordered
    (late: dropped), forecasts of the wrong period (rejected) and good ones (taken),
    datagrams of another format, an encoder reading sent twice (late) and 20 ticks without a
    reading (stale: the observer's fault path). Every torque is finite and within its limits."""
    ticks, origin = 800, program.controller.reference.origin
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + 400_000_000
    me = Link(epoch_ns=epoch)
    ports = [Link(epoch_ns=epoch) for _ in range(2)]
    controller_port, robot_port = (p.port for p in ports)
    for p in ports:
        p.close()
    robot = Link(robot_port, epoch)
    out = tmp_path / "run"
    proc = subprocess.Popen([str(program.program), "--epoch", str(epoch), "--ticks", str(ticks),
                             "--port", str(controller_port), "--robot-port", str(robot_port),
                             "--out", str(out), "--priority", "1",
                             "--origin", *(repr(float(v)) for v in origin)])
    q0, taus = program.controller.mpc.arm.q0, []
    try:
        for tick in range(ticks):
            _until_tick(epoch, tick - 0.5)
            if not 300 <= tick < 320:
                robot.send(controller_port, "measured_js", tick * TS, [q0])
            if tick == 500:
                robot.seq["measured_js"] -= 1  # the same number again: late
                robot.send(controller_port, "measured_js", tick * TS, [q0])
            if tick % 15 == 1:
                k = tick // 15
                if k == 10:
                    me.seq["measured_cp"] += 2  # two samples lost
                z = 1e-3 * np.array([[np.sin(tick * TS * 7.5), 0.0, 0.0]])
                if k == 20:  # a sample from before, reordered: late
                    seq = me.seq["measured_cp"]
                    me.seq["measured_cp"] = seq - 3
                    me.send(controller_port, "measured_cp", (tick - 46) * TS, z)
                    me.seq["measured_cp"] = seq
                me.send(controller_port, "measured_cp", (tick - 1) * TS, z)
                nodes = 1e-3 * np.sin(7.5 * ((tick - 1) * TS + 15 * TS * np.arange(5)))
                points = np.column_stack([nodes, np.zeros(5), np.zeros(5)])
                period = 15 * TS if k != 12 else 0.01
                me.send(controller_port, "forecast_cp", (tick - 1) * TS, points, period=period)
            if tick == 600:
                me.sock.sendto(b"not a message", ("127.0.0.1", controller_port))
            while (message := robot.receive(timeout=0.0)) is not None:
                taus.append(message.values[0])
        assert proc.wait(timeout=30) == 0
    finally:
        proc.kill()
        me.close()
        robot.close()
    result = json.loads(Path(f"{out}.json").read_text())
    assert result["ticks"] == ticks
    assert (result["measured_cp"]["lost"], result["measured_cp"]["late"]) == (2, 1)
    assert result["measured_js"]["late"] == 1 and result["bad"] == 1
    assert result["forecasts_rejected"] == 1 and result["counts"]["external"] > 20
    assert result["counts"]["missing"] >= 2 and result["stale_encoders"] >= 20
    assert result["served"]["external"] > 0 and result["encoder_held"] >= 20
    limit = np.asarray(program.controller.torque_limit)
    taus = np.array(taus)
    assert np.isfinite(taus).all() and (np.abs(taus) <= limit).all()
    assert np.fromfile(f"{out}.wake", dtype=np.int64).size + result["ticks_behind"] == ticks
