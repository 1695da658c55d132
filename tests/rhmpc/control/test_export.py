"""`rhmpc export` and the one logic kept in two languages: the RLS predictor.

The controller is one library (:class:`rhmpc.control.controller.Controller`). The RLS predictor
exists twice: in :mod:`rhmpc.predictors` (what a simulation runs and a researcher edits) and in
the library (``rhmpc_reference.c``), for a target with no predictor process (the decision
record *One controller*). The equivalence test holds the two together: the same library driven
by the Python predictor and by its own, in lockstep, fed the same encoder angles and samples
while the plant follows the first one's torque: |τ_C − τ_Python| ≤ 1e-6 τ_max on every tick, and
the same status, source, level and counters (measured ≈ 1e-12: the same arithmetic in another
summation order). The rest: the export's files, its build, its key, its symbols.
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from rhmpc.bench.ticks import heart_like_reference
from rhmpc.cli import main
from rhmpc.control.export import ExportError, export_controller
from rhmpc.control.export.binding import missing_toolchain
from rhmpc.experiment import RunConfig
from rhmpc.experiment.assembly import build_controller, deployable
from rhmpc.robots import load_robot
from rhmpc.sim.plant import make_plant

NO_TOOLCHAIN = missing_toolchain()
needs_cc = pytest.mark.skipif(NO_TOOLCHAIN is not None, reason=NO_TOOLCHAIN or "")
TOL = 1e-6  # of τ_max, every tick

#: Settings that take the other paths of the step: parameter-dependent bounds active on the
#: trajectory (levels 1, 2 and 3 of the screening cascade, max_iter failures and the carried
#: iterate), few iterations; the one-step predictor, a fixed gate floor, no reference guard.
JOINT_BOUNDS = {"mpc.joint_lower": (-0.015, -0.01, 1.57079633 - 0.03),
                "mpc.joint_upper": (0.015, 0.01, 1.57079633 + 0.03)}
VARIANTS = {
    "default": {},
    "joint-bounds": {**JOINT_BOUNDS, "predictor": "one-step"},
    "fixed-gate": {"mpc.max_iter": 15, "reference.outlier_gate": 1e-3},
    "few-iterations": {**JOINT_BOUNDS, "mpc.max_iter": 5, "mpc.plan_fallback_ticks": 3,
                       "reference.guard_speed": 0.0},
}


def pair(changes: dict, rate: float = 257.0):
    """The controller of the default run with ``changes`` driven by the Python predictor, and
    the same library driven by its own RLS predictor (``internal``)."""
    config = RunConfig().replace(**changes)
    python = deployable(config, rate)
    ref = python.reference
    twin = type(ref)(type(ref.predictor)(ref.dt, ref.predictor.settings), ref.Ts, ref.N,
                     ref.refresh_ticks, ref.settings)
    twin.place(ref.origin, ref.center)
    c = build_controller(config, python.mpc.arm.robot, python.mpc.arm, twin, "c")
    return python, c


def lockstep(python, c, ticks: int, samples, faults=None, reading=None
             ) -> tuple[np.ndarray, list]:
    """Both controllers on the ideal plant driven by the first one's torque; ``samples(k)`` gives
    the refreshes of tick k as (z, stamp); returns each tick's |τ_C − τ_Python| / τ_max and
    the ticks whose status, source or level differ."""
    robot = load_robot("phantom")
    plant = make_plant(robot, python.mpc.arm, python.mpc.arm.Ts)
    err, differ = np.zeros(ticks), []
    for k in range(ticks):
        if faults is not None:
            faults(k, python, c)
        for z, stamp in samples(k):
            python.refresh(k, z, stamp)
            c.refresh(k, z, stamp)
        q = plant.encoders() if reading is None else reading(k, plant.encoders())
        tp, tc = python.step(k, q), c.step(k, q)
        err[k] = np.max(np.abs(tc - tp) / python.torque_limit)
        ps, cs = python.stats, c.stats
        if (ps.status, ps.source, ps.level) != (cs.status, cs.source, cs.level):
            differ.append((k, ps.status, ps.source, ps.level, cs.status, cs.source, cs.level))
        plant.step(tp)
    return err, differ


def bench_samples(Ts: float, ticks: int, every: int = 15, seed: int = 0, jump: float = 2e-3):
    """The bench's heart-like motion with jumps of ``jump`` [m] every 1000 ticks, sampled every
    ``every`` ticks one tick late, centred."""
    traj = heart_like_reference(ticks + 2, Ts, np.random.default_rng(seed), np.zeros(3),
                                jump=jump, jump_every=1000)

    def samples(k):
        return [(traj[k - 1], (k - 1) * Ts)] if k % every == 1 else []

    return samples


def assert_same_counters(python, c):
    ps, cs = python.stats, c.stats
    assert (cs.ticks, cs.screened, cs.boxed) == (ps.ticks, ps.screened, ps.boxed)
    assert cs.fallbacks == ps.fallbacks and cs.failures == ps.failures
    counts = {k: v for k, v in python.predictor_counts.items() if v}
    assert dict(c.predictor_counts) == counts


@needs_cc
@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.slow
def test_the_librarys_rls_is_the_python_predictor_tick_for_tick(variant):
    """4000 ticks of the bench's motion with 2-mm jumps (torque bounds, and with joint bounds the
    envelope, active after each jump)."""
    python, c = pair(VARIANTS[variant])
    err, differ = lockstep(python, c, 4000, bench_samples(python.mpc.arm.Ts, 4000))
    assert differ == []
    assert err.max() <= TOL, (err.max(), int(err.argmax()))
    assert_same_counters(python, c)
    assert python.stats.screened > 0


@needs_cc
@pytest.mark.slow
def test_faults_are_handled_alike():
    """Forced solver failures, missing and non-finite samples, an echo outlier of 5 mm, a 1e200
    sample, encoder readings that are not finite and encoders stuck for 0.1 s: the same
    torques, counters, gate and encoder events, and the torques stay finite."""
    python, c = pair({"reference.outlier_gate": 1e-3})
    base = bench_samples(python.mpc.arm.Ts, 3000)

    def samples(k):
        out = base(k)
        if out and k % 600 == 286:
            return [(None, out[0][1])]
        if out and k % 700 == 331:
            return [(np.array([np.nan, 0.0, 0.0]), out[0][1])]
        if out and k % 500 == 376:
            return [(out[0][0] + np.array([5e-3, 0.0, 0.0]), out[0][1])]
        if out and k == 2101:
            return [(np.full(3, 1e200), out[0][1])]
        return out

    def faults(k, python, c):
        if k % 700 == 350:
            python.force_failures(4)
            c.force_failures(4)

    stuck = {}

    def reading(k, q):  # readings not finite, and encoders stuck for 0.1 s from tick 1600
        if 1600 <= k < 1800:
            return stuck.setdefault("q", q.copy())
        return np.full_like(q, np.nan) if k in (1200, 1201, 2500) else q

    err, differ = lockstep(python, c, 3000, samples, faults, reading)
    assert differ == [] and err.max() <= TOL
    assert_same_counters(python, c)
    counts = python.predictor_counts
    assert counts["missing"] >= 10 and counts["outliers_rejected"] >= 3
    assert python.stats.failures.get("injected") == 16
    assert python.stats.failures.get("encoder_fault", 0) > 0  # the stuck encoders: braking
    assert c.encoder_counts == python.encoder_counts and python.encoder_counts["held"] > 100


@needs_cc
@pytest.mark.slow
def test_a_slow_sensor_refreshes_on_each_sample_alike():
    """A 25-Hz video-like sensor: the sensor clock (the predictor at 40 ms, the forecast across
    the latency), samples 60 ms old on arrival."""
    python, c = pair({}, rate=25.0)
    Ts = python.mpc.arm.Ts
    traj = heart_like_reference(8000, Ts, np.random.default_rng(1), np.zeros(3))

    def samples(k):
        return [(traj[k - 120], (k - 120) * Ts)] if k >= 120 and k % 80 == 40 else []

    err, differ = lockstep(python, c, 6000, samples)
    assert differ == [] and err.max() <= TOL
    assert_same_counters(python, c)
    assert python.reference.dt == pytest.approx(0.04)


@needs_cc
@pytest.mark.slow
def test_closed_loop_own_rls_against_python_on_the_main_job(tmp_path):
    """`simulate --controller c` (the library's own RLS) on the default job (4 s) and on a
    25-Hz recording (a video track's 0.05-mm noise): the RMS within 1 % of the Python
    predictor's run (the plant integrates torques that differ only by rounding)."""
    from rhmpc.experiment import run_experiment

    t = np.arange(0, 8, 1 / 25)
    z = np.c_[2.5 * np.sin(2 * np.pi * 1.2 * t), 1.5 * np.sin(2 * np.pi * 1.2 * t + 1),
              np.sin(2 * np.pi * 0.25 * t)]
    z += np.random.default_rng(0).normal(scale=0.05, size=z.shape)
    z += [40.0, -25.0, 60.0]  # the tracker's frame: the controllers place its mean
    path = tmp_path / "video.csv"
    np.savetxt(path, np.c_[t, z], delimiter=",", header="t,x,y,z", comments="")
    for config in (RunConfig(seed=2).replace(**{"loop.duration": 4.0}),
                   RunConfig(data=str(path), sensor="recorded").replace(
                       **{"loop.duration": 7.0})):
        rms = [run_experiment(config, implementation=way)[1]["rms_error_mm"]
               for way in ("python", "c")]
        assert abs(rms[1] / rms[0] - 1) <= 0.01, rms


@needs_cc
@pytest.mark.slow
def test_the_sensors_frame_is_placed_alike():
    """Samples in a tracker's frame 50 mm away, both controllers placed with that frame's
    point at the tool's home: the same torques and points, tick for tick."""
    python, c = pair({})
    center = np.array([0.03, -0.02, 0.05])
    python.reference.place(python.reference.origin, center)
    c.place(python.reference.origin, center)
    base = bench_samples(python.mpc.arm.Ts, 2000)

    def samples(k):
        return [(z + center, stamp) for z, stamp in base(k)]

    err, differ = lockstep(python, c, 2000, samples)
    assert differ == [] and err.max() <= TOL, (err.max(), int(err.argmax()))
    np.testing.assert_allclose(c.horizon(1999), python.reference.horizon(1999), atol=1e-9)


@needs_cc
@pytest.mark.slow
def test_two_controllers_on_one_library_do_not_share_the_solver():
    python, c = pair({})
    _, other = pair({})
    assert other.library != c.library  # a private copy: OSQP's workspace is static
    samples = bench_samples(python.mpc.arm.Ts, 500)
    q = python.mpc.arm.q0
    for k in range(500):
        for z, stamp in samples(k):
            c.refresh(k, z, stamp)
            other.refresh(k, z, stamp)
        np.testing.assert_array_equal(c.step(k, q), other.step(k, q))


@needs_cc
@pytest.mark.slow
def test_library_uses_no_heap_io_or_locks():
    """The shared library's undefined symbols: the monotonic clock, memset/memcpy/memmove and
    libm; no malloc, no printf, no lock."""
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("nm (binutils) not found")
    _, c = pair({})
    out = subprocess.run([nm, "-D", "--undefined-only", c.library], capture_output=True,
                         text=True, check=True).stdout
    symbols = {line.split()[-1].split("@")[0] for line in out.splitlines() if line.strip()}
    runtime = {"_ITM_deregisterTMCloneTable", "_ITM_registerTMCloneTable", "__cxa_finalize",
               "__gmon_start__", "__stack_chk_fail"}
    libm = {"sin", "cos", "sincos", "tanh", "sqrt", "fabs", "floor", "ceil", "exp"}
    assert symbols - runtime <= {"clock_gettime", "memset", "memcpy", "memmove"} | libm, symbols
    assert "clock_gettime" in symbols  # the calls time themselves


def test_export_refuses_what_the_c_does_not_run(tmp_path):
    python = deployable(RunConfig(predictor="ekf"), 257.0)  # its library: ekf feeds it
    with pytest.raises(ExportError, match="one-step or generalized"):
        export_controller(python, tmp_path / "out", robot="phantom")


def test_export_keeps_a_users_files(tmp_path, capsys):
    """A non-empty folder is refused without --force; with it only the export's files are
    written, and a user's file stays."""
    out = tmp_path / "proj"
    (out / "osqp").mkdir(parents=True)
    (out / "osqp" / "notes.txt").write_text("notes")
    (out / "CMakeLists.txt").write_text("# my build")
    assert main(["export", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--force" in err
    assert (out / "CMakeLists.txt").read_text() == "# my build"
    assert main(["export", str(out), "--force"]) == 0
    assert (out / "osqp" / "notes.txt").read_text() == "notes"
    assert "rhmpc_step" in (out / "rhmpc.h").read_text()


def test_export_of_the_exact_future_is_one_line(tmp_path, capsys):
    path = tmp_path / "exact.toml"
    path.write_text('predictor = "exact"\n')
    assert main(["export", str(tmp_path / "out"), "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "predictor" in err


@pytest.mark.slow
@needs_cc
def test_cmake_builds_the_libraries_and_the_example_runs(tmp_path, capsys):
    """The exported folder alone: cmake builds librhmpc.a and the example, whose fixed-rate
    loop with a fake sensor refreshes and steps."""
    if shutil.which("cmake") is None:
        pytest.skip("cmake not found")
    src, build = tmp_path / "src", tmp_path / "build"
    assert main(["export", str(src)]) == 0
    capsys.readouterr()
    for cmd in (["cmake", "-S", str(src), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release"],
                ["cmake", "--build", str(build), "--parallel", "2"]):
        subprocess.run(cmd, check=True, capture_output=True)
    assert (build / "librhmpc.a").is_file()
    run = subprocess.run([str(build / "rhmpc_example"), "0.5"], capture_output=True, text=True,
                         check=True, timeout=60)
    assert "refreshes" in run.stdout and "status solved" in run.stdout, run.stdout
    for bad in ("inf", "nan", "-1", "1e9", "2s"):  # a duration it refuses, on one line
        run = subprocess.run([str(build / "rhmpc_example"), bad], capture_output=True,
                             text=True, timeout=60)
        assert run.returncode == 2 and run.stdout == "" and len(run.stderr.splitlines()) == 1
    from rhmpc.runtime.build import missing_toolchain

    if missing_toolchain() is not None:
        pytest.skip(missing_toolchain())
    udp = tmp_path / "udp-build"  # the transport beside it: the controller's program, a client
    for cmd in (["cmake", "-S", str(src / "udp"), "-B", str(udp)], ["cmake", "--build", str(udp)]):
        subprocess.run(cmd, check=True, capture_output=True)
    assert (udp / "rhmpc_sil_controller").is_file() and (udp / "rhmpc_robot_client").is_file()


@needs_cc
@pytest.mark.parametrize("which", ["python", "c"])
def test_forecasts_alone_drive_the_reference(which):
    """A controller given forecasts and never a sample (a deployment whose predictor runs in
    another process, its own RLS off): its points are the forecast's, placed, from the first
    one on. A forecast stamped after the tick is refused and does not shut out the next ones."""
    python, c = pair({})
    ctl = python if which == "python" else c
    Ts, origin = python.mpc.arm.Ts, python.reference.origin
    center = np.array([0.01, 0.02, -0.03])
    ctl.reference.place(origin, center)
    points = center + 1e-3 * np.column_stack([np.linspace(0.0, 4.0, 6), np.zeros(6),
                                              np.zeros(6)])
    dt = python.reference.dt
    assert ctl.forecast(10, 9 * Ts, points)
    horizon = ctl.horizon(10)
    expected_x = origin[0] + 1e-3 * 4.0 * ((11 + np.arange(len(horizon))) * Ts - 9 * Ts) / (5 * dt)
    np.testing.assert_allclose(horizon[:, 0], expected_x, atol=1e-9)
    np.testing.assert_allclose(horizon[:, 1:], np.broadcast_to(origin[1:], (len(horizon), 2)),
                               atol=1e-12)
    assert not ctl.forecast(20, 1000.0, points)  # from the future: refused
    assert ctl.forecast(30, 29 * Ts, points)     # the next one is taken
    assert ctl.predictor_counts["external_rejected"] == 1


@needs_cc
def test_the_tool_position_is_pinocchios():
    """``rhmpc_tool_position`` (the generated forward kinematics) against Pinocchio's frame
    placement at random postures within the joint limits: 1e-12 m."""
    import ctypes

    import pinocchio as pin

    python, c = pair({})
    robot = python.mpc.arm.robot
    lower, upper = robot.position_limits
    rng = np.random.default_rng(3)
    lib, p = c._lib, np.zeros(3)
    for _ in range(20):
        q = rng.uniform(lower, upper)
        lib.rhmpc_tool_position(q.ctypes.data_as(ctypes.c_void_p),
                                p.ctypes.data_as(ctypes.c_void_p))
        data = robot.create_data()
        pin.framesForwardKinematics(robot.model, data, q)
        np.testing.assert_allclose(p, data.oMf[robot.ee_frame_id].translation, atol=1e-12)
    limits = [(ctypes.c_double * c.nu).in_dll(lib, name) for name in ("rhmpc_q_min", "rhmpc_q_max")]
    np.testing.assert_array_equal([list(v) for v in limits], [lower, upper])


def test_the_exports_key_covers_its_templates(monkeypatch, tmp_path):
    """An edit to a template alone gives another key (the build caches by that key)."""
    from rhmpc.control.export import generate as gen

    controller = deployable(RunConfig(), 257.0)
    before = gen._generate_into(controller, "phantom", tmp_path / "a")[2]
    real = gen.files

    class Edited:
        def __init__(self, inner):
            self.inner = inner

        def joinpath(self, *parts):
            path = self.inner.joinpath(*parts)
            return _EditedFile(path) if parts[-1] == "rhmpc_mpc.c" else (
                Edited(path) if not parts[-1].endswith((".c", ".h", ".txt")) else path)

    monkeypatch.setattr(gen, "files", lambda package: Edited(real(package)))
    (tmp_path / "b").mkdir()
    after = gen._generate_into(controller, "phantom", tmp_path / "b")[2]
    assert after != before


class _EditedFile:
    """A template file read back with one comment added."""

    def __init__(self, path):
        self.path = path

    def read_bytes(self) -> bytes:
        return self.path.read_bytes() + b"/* edited */\n"

    def read_text(self) -> str:
        return self.read_bytes().decode()
