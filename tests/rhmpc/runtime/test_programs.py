"""The C side of the wire: the robot-side client under spoofed and implausible torques, the
controller's program under lost, reordered, foreign and implausible traffic and its supervisor,
and the C decoder fuzzed under AddressSanitizer and UndefinedBehaviorSanitizer against the
Python codec. The counts are asserted, never a latency (the host's load decides those)."""

from __future__ import annotations

import hmac
import json
import os
import re
import struct
import subprocess
import time
from importlib.resources import files
from pathlib import Path

import numpy as np
import pytest

from rhmpc.compiled import compiler
from rhmpc.runtime.build import missing_toolchain
from rhmpc.runtime.wire import Dropped, Link, Message, bind, new_key, run_clock, seal, unseal
from rhmpc.runtime.wire.codec import HEAD, OFFSETS
from rhmpc.runtime.wire.table import DROPS, REPORT, VERSION

C = Path(str(files("rhmpc.runtime").joinpath("export")))
TS = 0.5e-3
needs_build = pytest.mark.skipif(missing_toolchain() is not None,
                                 reason=missing_toolchain() or "")


def _until_tick(epoch: int, tick: float) -> None:
    while (left := tick * TS - run_clock(epoch)) > 0:
        time.sleep(min(left, 0.01))


def _key_file(folder: Path, key: bytes) -> Path:
    path = folder / "run.key"
    path.write_text(key.hex() + "\n")
    path.chmod(0o600)
    return path


@pytest.fixture(scope="module")
def built():
    """The controller's program and the robot-side client of the default run (exported and
    built with CMake)."""
    if missing_toolchain() is not None:
        pytest.skip(missing_toolchain())
    from rhmpc.experiment import RunConfig
    from rhmpc.runtime.build import build_controller

    return build_controller(RunConfig(), 257.0)


@needs_build
@pytest.mark.slow
def test_no_spoofed_or_implausible_torque_reaches_the_robots_drivers(built, tmp_path):
    """The client against a Python controller that answers each reading with that tick's
    torque, while a foreign sender (no key, another key) and the controller itself (NaN,
    1e300, over the limit, stamped 1000 s ahead, a number far ahead) try other torques, and
    the controller falls silent for 60 ticks. Every torque the drivers got is the controller's
    plausible one of that tick; the silence ends in the safe state after the watchdog."""
    key, ticks = new_key(), 600
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + 400_000_000
    controller = Link(bind(), key, epoch, accepts=("measured_js",))
    robot_sock = bind()
    robot_port = robot_sock.getsockname()[1]
    robot_sock.close()
    foreign, other = bind(), new_key()
    log = tmp_path / "applied.csv"
    client = subprocess.Popen([str(built.client), "--key-file", str(_key_file(tmp_path, key)),
                               "--controller-port", str(controller.port), "--port",
                               str(robot_port), "--epoch", str(epoch), "--ticks", str(ticks),
                               "--log", str(log)], stdout=subprocess.PIPE, text=True)
    good = {}
    try:
        while (message := _newest(controller)) is not None:
            tick = round(message.stamp / TS)
            if not 300 <= tick < 360:  # else silent
                good[tick] = np.array([0.1, 0.2, 0.3]) * (1 + (tick % 7) / 10)
                controller.send(robot_port, "servo_jf", message.stamp, [good[tick]])
            _spoof(foreign, controller, robot_port, tick, message.stamp, other)
        out = client.communicate(timeout=10)[0]
    finally:
        client.kill()
        controller.close()
        foreign.close()
    rows = [line.split(",") for line in log.read_text().splitlines()]
    modes = [r[1] for r in rows]
    torques = np.array([[float(v) for v in r[2:]] for r in rows])
    assert np.isfinite(torques).all() and np.abs(torques).max() <= 1.0
    taken = [i for i, m in enumerate(modes) if m == "torque"]
    assert len(taken) > 20  # a Python controller on a busy host misses some ticks
    for i in taken:
        np.testing.assert_array_equal(torques[i], good[i])  # that tick's, the controller's
    last = -10**9  # the watchdog: a hold within 20 ticks of the last torque, then the safe state
    for i, mode in enumerate(modes):
        last = i if mode == "torque" else last
        assert mode == "torque" or mode == ("hold" if i - last <= 20 else "safe"), (i, mode)
    assert "torque" not in modes[300:360] and set(modes[321:360]) == {"safe"}
    counts = dict(re.findall(r"(\w+) (\d+)", out.split("dropped", 1)[1]))
    assert int(counts["unauthenticated"]) > 0 and int(counts["implausible"]) > 0
    assert int(counts["far_ahead"]) > 0


def _newest(link: Link):
    """The newest reading that has arrived (a Python controller behind its robot skips to
    it), or None after 2 s without one."""
    message = link.receive(timeout=2.0)
    while message is not None and (later := link.receive(timeout=0.0)) is not None:
        message = later
    return message


def _spoof(foreign, controller: Link, port: int, tick: int, stamp: float, other: bytes) -> None:
    """Every 10th tick, one spoof of each sort."""
    if tick % 10:
        return
    address = ("127.0.0.1", port)
    body = HEAD.pack(b"RHMP", VERSION, 4, tick, stamp, stamp, stamp, 0.0, 1, 3, 0)
    foreign.sendto(body + np.full(3, 50.0).tobytes() + bytes(32), address)  # no key
    foreign.sendto(seal(Message("servo_jf", tick, stamp, np.full((1, 3), 50.0),
                                sent=controller.now()), other), address)  # another key
    for values, at in (([[np.nan, 0.0, 0.0]], stamp), ([[1e300, 0.0, 0.0]], stamp),
                       ([[9.0, 0.0, 0.0]], stamp), ([[0.5, 0.5, 0.5]], stamp + 1000.0)):
        controller.send(port, "servo_jf", at, values)  # the key's own, implausible
    seq = controller.seq["servo_jf"]
    controller.seq["servo_jf"] = seq + (1 << 40)
    controller.send(port, "servo_jf", stamp, [[0.7, 0.7, 0.7]])  # a number far ahead
    controller.seq["servo_jf"] = seq + 1


def _controller(built, folder: Path, ticks: int, settle: float):
    """The controller's program on a clock 0.4 s ahead, placed at the tool's home, its socket
    inherited, a silent robot stopping it only after 10 s (a busy host stalls the test's own
    process); a sender and a robot's end of the run's key. Its results go to FOLDER/run."""
    key = new_key()
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + 400_000_000
    me, robot = Link(bind(), key, epoch), Link(bind(), key, epoch, accepts=("servo_jf",))
    sock = bind()
    proc = subprocess.Popen([str(built.program), "--key-file", str(_key_file(folder, key)),
                             "--socket-fd", str(sock.fileno()), "--epoch", str(epoch),
                             "--ticks", str(ticks), "--robot-port", str(robot.port),
                             "--out", str(folder / "run"), "--priority", "1", "--settle",
                             repr(settle), "--robot-timeout", "10", "--origin",
                             *(repr(float(v)) for v in built.controller.reference.origin)],
                            pass_fds=(sock.fileno(),), stderr=subprocess.PIPE, text=True)
    return proc, me, robot, sock, epoch


def _close(proc, sock, *ends) -> None:
    """The controller's program ended (killed if it still runs), the test's sockets closed."""
    proc.kill()
    for end in ends:
        end.close()
    sock.close()


@needs_build
@pytest.mark.slow
def test_the_controller_counts_and_survives_bad_traffic(built, tmp_path):
    """0.4 s of ticks: samples with a gap of 2 (lost: missing samples) and one reordered
    (late: dropped), forecasts of the wrong period and a metre off (implausible) and good ones
    (taken), datagrams of no key and of another key, an encoder reading sent twice (late) and
    20 ticks without a reading (stale: the observer's fault path). Every torque is finite and
    within its limits."""
    ticks, out = 800, tmp_path / "run"
    proc, me, robot, sock, epoch = _controller(built, tmp_path, ticks, settle=100.0)
    port, q0, taus = sock.getsockname()[1], built.controller.mpc.arm.q0, []
    foreign = bind()
    try:
        for tick in range(ticks):
            _until_tick(epoch, tick - 0.5)
            _traffic(me, robot, foreign, port, tick, q0)
            while (message := robot.receive(timeout=0.0)) is not None:
                taus.append(message.values[0])
        assert proc.wait(timeout=30) == 0
    finally:
        _close(proc, sock, me, robot, foreign)
    result = json.loads(Path(f"{out}.json").read_text())
    assert result["ticks"] == ticks and result["stopped"] == ""
    assert result["lost"]["measured_cp"] == 2 and result["dropped"]["late"] == 2
    assert result["dropped"]["implausible"] == 2 and result["dropped"]["unauthenticated"] == 2
    assert result["dropped"]["malformed"] == 1 and result["counts"]["external"] > 20
    assert result["counts"]["missing"] >= 2 and result["stale_encoders"] >= 20
    assert result["served"]["external"] > 0 and result["encoder_held"] >= 20
    limit = np.asarray(built.controller.torque_limit)
    taus = np.array(taus)
    assert np.isfinite(taus).all() and (np.abs(taus) <= limit).all()
    assert np.fromfile(f"{out}.wake", dtype=np.int64).size + result["ticks_behind"] == ticks
    assert set(result["dropped"]) == {name for name, _ in DROPS}
    assert set(result) == {key for key, _ in REPORT}  # the report's keys are the table's


def _traffic(me: Link, robot: Link, foreign, port: int, tick: int, q0) -> None:
    """One tick of the controller test's traffic."""
    if not 300 <= tick < 320:
        robot.send(port, "measured_js", tick * TS, [q0])
    if tick == 500:
        robot.seq["measured_js"] -= 1  # the same number again: late
        robot.send(port, "measured_js", tick * TS, [q0])
    if tick % 15 == 1:
        k, now = tick // 15, me.now() - TS  # stamped by the clock: a stall here is no stale one
        if k == 10:
            me.seq["measured_cp"] += 2  # two samples lost
        z = 1e-3 * np.array([[np.sin(now * 7.5), 0.0, 0.0]])
        if k == 20:  # a sample from before, reordered: late
            seq = me.seq["measured_cp"]
            me.seq["measured_cp"] = seq - 3
            me.send(port, "measured_cp", now - 45 * TS, z)
            me.seq["measured_cp"] = seq
        me.send(port, "measured_cp", now, z)
        nodes = 1e-3 * np.sin(7.5 * (now + 15 * TS * np.arange(5)))
        points = np.column_stack([nodes, np.zeros(5), np.zeros(5) + 1.0 * (k == 14)])
        period = 15 * TS if k != 12 else 0.01
        me.send(port, "forecast_cp", now, points, period=period)
    if tick == 600:
        foreign.sendto(b"not a message", ("127.0.0.1", port))
    if tick in (610, 620):
        foreign.sendto(seal(Message("measured_js", 10**6, tick * TS, np.array([q0]) + 0.1,
                                    sent=tick * TS), new_key()), ("127.0.0.1", port))


@needs_build
@pytest.mark.slow
def test_the_controller_fuses_readings_that_come_late(built, tmp_path):
    """0.5 s of readings each sent 3 ticks after its tick (an arm behind a middleware), then
    100 ticks of readings 50 ticks old (past the observer's 40-tick window): the first are fused
    late and counted, the others are no reading; the supervisor, which counts a tick's reading
    as missing only once it can no longer be fused, lets the run end; every torque is finite."""
    ticks, out = 1100, tmp_path / "run"
    proc, me, robot, sock, epoch = _controller(built, tmp_path, ticks, settle=100.0)
    port, q0, taus = sock.getsockname()[1], built.controller.mpc.arm.q0, []
    try:
        for tick in range(ticks):
            _until_tick(epoch, tick - 0.5)
            late = 3 if tick < 1000 else 50
            if tick >= late:
                robot.send(port, "measured_js", (tick - late) * TS, [q0])
            while (message := robot.receive(timeout=0.0)) is not None:
                taus.append(message.values[0])
        assert proc.wait(timeout=30) == 0, proc.stderr.read()[-500:]
    finally:
        _close(proc, sock, me, robot)
    result = json.loads(Path(f"{out}.json").read_text())
    assert result["ticks"] == ticks and result["stopped"] == ""
    assert result["late_readings"] > 800 and 3 <= result["delay_max"] <= 40
    assert result["stale_encoders"] >= 100  # the readings past the window, and the first ticks
    assert np.isfinite(np.array(taus)).all()


@needs_build
@pytest.mark.slow
def test_the_supervisor_stops_when_the_tool_leaves_the_poi(built, tmp_path):
    """Readings at rest at home while the samples say the POI sits 8 mm away: after the
    settling time the controller stops the run (no torque goes out after it), exits 3 and
    names the cause."""
    ticks, out = 2000, tmp_path / "run"
    proc, me, robot, sock, epoch = _controller(built, tmp_path, ticks, settle=0.2)
    port, q0, torques_after = sock.getsockname()[1], built.controller.mpc.arm.q0, 0
    try:
        for tick in range(ticks):
            _until_tick(epoch, tick - 0.5)
            if proc.poll() is not None:
                break
            robot.send(port, "measured_js", tick * TS, [q0])
            if tick % 20 == 0 and tick >= 20:
                me.send(port, "measured_cp", (tick - 2) * TS, [[0.0, 0.008, 0.0]])
        code, err = proc.wait(timeout=30), proc.stderr.read()
        while (message := robot.receive(timeout=0.0)) is not None:
            torques_after += message.stamp > 0.25
    finally:
        _close(proc, sock, me, robot)
    result = json.loads(Path(f"{out}.json").read_text())
    assert code == 3 and "left its 5-mm bound" in result["stopped"] and "stopped" in err
    assert 400 <= result["ticks"] < 600 and torques_after < 50


FUZZ_HARNESS = r"""
#include "rhmpc_wire.h"
#include <stdio.h>
#include <stdlib.h>
/* Reads (u32 length, bytes) records from stdin; prints each one's verdict, one per line. */
int main(int argc, char **argv) {
  rhmpc_wire_key_t key;
  char why[256];
  static unsigned char buf[70000];
  static double values[8192];
  rhmpc_wire_t m;
  if (argc < 2 || rhmpc_wire_key_read(&key, argv[1], why, sizeof why) != 0) return 2;
  unsigned int n;
  while (fread(&n, 4, 1, stdin) == 1) {
    if (n > sizeof buf || fread(buf, 1, n, stdin) != n) return 3;
    printf("%d\n", rhmpc_wire_unseal(&key, buf, n, 3, &m, values, 8192));
  }
  return 0;
}
"""


def _corpus(rng: np.random.Generator, key: bytes) -> list[bytes]:
    """Random, truncated and mutated datagrams, and messages whose header lies about their
    size (resealed, so that the parse after the code is reached)."""
    kinds = {"measured_cp": (1, 3), "forecast_cp": (50, 3), "measured_js": (1, 3),
             "servo_jf": (1, 3)}
    valid = [seal(Message(kind, int(rng.integers(0, 2**63)), float(rng.normal()),
                          rng.normal(size=shape), period=0.04), key)
             for kind, shape in kinds.items() for _ in range(5)]
    out = [rng.bytes(int(rng.integers(0, 2000))) for _ in range(300)]
    for data in valid:
        out += [data, data[: int(rng.integers(0, len(data)))]]
        for _ in range(20):
            mutated = bytearray(data)
            for at in rng.integers(0, len(data), size=int(rng.integers(1, 4))):
                mutated[at] ^= 1 << int(rng.integers(0, 8))
            out.append(bytes(mutated))
        body = bytearray(data[:-32])
        for field, value in (("rows", 65535), ("width", 65535), ("kind", 0), ("kind", 99),
                             ("version", 1), ("rows", 0), ("width", 2)):
            lie = bytearray(body)
            struct.pack_into("<H", lie, OFFSETS[field], value)
            out.append(bytes(lie) + hmac.digest(key, bytes(lie), "sha256"))
    big = HEAD.pack(b"RHMP", VERSION, 2, 0, 0.0, 0.0, 0.0, 0.04, 65535, 65535, 0)
    out.append(big + bytes(32))  # rows x width far beyond any datagram
    return out


def _python_verdict(data: bytes, key: bytes) -> str:
    try:
        unseal(data, key, joints=3)
        return "taken"
    except Dropped as drop:
        return drop.reason


@pytest.mark.slow
@pytest.mark.skipif(compiler() is None, reason="no C compiler")
def test_the_c_decoder_under_sanitizers_agrees_with_python(tmp_path):
    """A seeded corpus of random, truncated, bit-flipped and lying datagrams through
    rhmpc_wire_unseal built with -fsanitize=address,undefined (no recovery): no report, and the
    same verdict as the Python codec for every one."""
    source = tmp_path / "fuzz.c"
    source.write_text(FUZZ_HARNESS)
    program = tmp_path / "fuzz"
    build = subprocess.run([compiler(), "-std=c11", "-D_POSIX_C_SOURCE=200809L", "-g", "-O1",
                            "-fsanitize=address,undefined",
                            "-fno-sanitize-recover=all", f"-I{C}", str(source), "-o",
                            str(program), "-lcrypto"], capture_output=True, text=True)
    if build.returncode != 0:
        pytest.skip(f"the sanitizers or libcrypto are not available: {build.stderr[-200:]}")
    key = new_key()
    corpus = _corpus(np.random.default_rng(2026), key)
    stream = b"".join(struct.pack("<I", len(d)) + d for d in corpus)
    done = subprocess.run([str(program), str(_key_file(tmp_path, key))], input=stream,
                          capture_output=True, env={**os.environ, "ASAN_OPTIONS":
                                                    "detect_leaks=0"})
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    assert b"runtime error" not in done.stderr and b"Sanitizer" not in done.stderr
    names = ["taken", *(name for name, _ in DROPS)]
    c = [names[int(v)] for v in done.stdout.split()]
    python = [_python_verdict(d, key) for d in corpus]
    assert len(c) == len(corpus) and c == python
    assert {"taken", "malformed", "unauthenticated"} <= set(c)


@needs_build
@pytest.mark.slow
def test_c_and_python_seal_the_same_bytes(built, tmp_path):
    """The robot-side client's first reading, sealed in C, is taken by the Python codec; and a
    torque sealed in Python is taken by the client (the test above): one format."""
    key = new_key()
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) + 200_000_000
    controller = bind()
    port = bind()
    robot_port = port.getsockname()[1]
    port.close()
    client = subprocess.Popen([str(built.client), "--key-file", str(_key_file(tmp_path, key)),
                               "--controller-port", str(controller.getsockname()[1]),
                               "--port", str(robot_port), "--epoch", str(epoch), "--ticks",
                               "3"], stdout=subprocess.PIPE)
    try:
        controller.settimeout(5.0)
        message = unseal(controller.recv(65536), key)
        assert message.kind == "measured_js" and message.seq == 0 and message.stamp == 0.0
    finally:
        client.wait(timeout=10)
        controller.close()
