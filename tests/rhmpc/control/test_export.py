"""`rhmpc export`: the compiled controller against the Python one, tick for tick.

The reference is the Python controller itself (:class:`RecedingHorizonMPC`), run on the same
inputs: the C code has its own implementation of the tick (screening, warm start, fallback
chain, clipping) and OSQP's generated solver, so any drift between the two shows up here.
Tolerance: |τ_C − τ_Python| ≤ 1e-6 τ_max on every tick (the issue's target); measured ≈ 2e-11
(the same OSQP iterations, rounding differences only), so the margin is 5 orders of magnitude.
Libraries are compiled once per test run (``built``); tests that need a compiler skip without one.
"""

from __future__ import annotations

import dataclasses
import shutil
import subprocess

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.control.export import (
    CController,
    ExportError,
    build_cached,
    export_controller,
    missing_toolchain,
)
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.settings import MPCSettings
from rhmpc.studies.bench import heart_like_reference
from robots import linearize, load_robot
from sim.loop.results import YARDSTICK_EVERY, YARDSTICK_PHASE

NO_TOOLCHAIN = missing_toolchain()
needs_cc = pytest.mark.skipif(NO_TOOLCHAIN is not None, reason=NO_TOOLCHAIN or "")
TOL = 1e-6  # of τ_max, every tick

#: Settings variants that exercise the other code paths of the tick: parameter-dependent
#: bounds (joint limits, active on the bench trajectory: levels 1, 2 and 3 of the screening
#: cascade), too few iterations (max_iter failures: plan fallback and the carried-over
#: iterate), every warm start mode, and OSQP on every tick.
VARIANTS = {
    "default": {},
    "joint-bounds-shift": dict(
        joint_lower=(-0.015, -0.01, 1.57079633 - 0.03),
        joint_upper=(0.015, 0.01, 1.57079633 + 0.03), warm_start="shift", max_iter=10,
    ),
    "keep-no-screening": dict(warm_start="keep", screening=False, max_iter=15),
    # level 2 off: the saturated ticks reach OSQP, whose 5 iterations are not enough
    "none-few-iterations": dict(warm_start="none", max_iter=5, plan_fallback_ticks=3,
                                box_screening=False),
}


@pytest.fixture(scope="session")
def arm():
    return linearize(load_robot("phantom"))


@pytest.fixture(scope="session")
def cache(tmp_path_factory):
    """One build cache per test run (shared with tests/rhmpc/studies/test_bench.py)."""
    return tmp_path_factory.getbasetemp() / "rhmpc-cache"


@pytest.fixture(scope="session")
def built(arm, cache):
    """Library path per variant, compiled on first use."""
    libs: dict[str, object] = {}

    def get(name: str):
        if name not in libs:
            mpc = RecedingHorizonMPC(arm, MPCSettings(**VARIANTS[name]))
            libs[name] = build_cached(mpc, "phantom", cache)
        return libs[name]

    return get


def twin(py, lib, **kwargs) -> CController:
    """The compiled controller of ``lib`` (``py``'s output offset computed in C)."""
    return CController(lib, **kwargs)


def bench_trajectory(arm, ticks: int, seed: int = 0) -> np.ndarray:
    """The bench's reference: heart-like motion with 2-mm jumps every 1000 ticks."""
    return heart_like_reference(ticks + 51, arm.Ts, np.random.default_rng(seed), arm.y0,
                                jump=2e-3, jump_every=1000)


def lockstep(arm, py, c, traj, ticks, faults=None):
    """Run both controllers on the linear model driven by the Python torque; per-tick records."""
    N = py.N
    tau_max = np.asarray(arm.torque_limit)
    x = np.zeros(arm.nx)
    err = np.zeros(ticks)
    differ = []
    for k in range(ticks):
        ref = traj[k + 1:k + 1 + N]
        xk = x
        if faults is not None:
            xk, ref = faults(k, x, ref, py, c)
        tp = py.step(xk, ref)
        tc = c.step(xk, ref)
        err[k] = np.max(np.abs(tc - tp) / tau_max)
        if (py.stats.status, py.stats.source, py.stats.level) != (c.status, c.source, c.level):
            differ.append((k, py.stats.status, py.stats.source, py.stats.level, c.status,
                           c.source, c.level))
        x = arm.A @ x + arm.B @ tp
    return err, differ


def inject_faults(k, x, ref, py, c):
    """Four forced solver failures every 700 ticks, a NaN state every 900."""
    if k % 700 == 350:
        py.force_failures(4)
        c.force_failures(4)
    if k % 900 == 450:
        x = x.copy()
        x[1] = np.nan
    return x, ref


def assert_same_counters(py, c):
    cs, ps = c.stats, py.stats
    assert cs.ticks == ps.ticks
    assert cs.screened == ps.screened
    assert cs.boxed == ps.boxed
    assert cs.fallbacks == ps.fallbacks
    assert cs.failures == ps.failures


@needs_cc
def test_bench_trajectory_torques_and_fallbacks_match_python(arm, built):
    """20 000 ticks of the bench trajectory (torque bounds active after every jump)."""
    py = RecedingHorizonMPC(arm, MPCSettings())
    c = twin(py, built("default"))
    ticks = 20_000
    err, differ = lockstep(arm, py, c, bench_trajectory(arm, ticks), ticks)
    assert differ == []
    assert err.max() <= TOL
    assert_same_counters(py, c)
    # the saturated ticks went to level 2 of the screening cascade (the torque-box QP), in C too
    assert 100 < py.stats.boxed < 2000 and c.stats.boxed == py.stats.boxed


@needs_cc
@pytest.mark.parametrize("variant", [v for v in VARIANTS if v != "default"])
def test_other_paths_match_python(arm, built, variant):
    """Joint bounds, max_iter failures and every warm-start mode, with injected faults."""
    py = RecedingHorizonMPC(arm, MPCSettings(**VARIANTS[variant]))
    c = twin(py, built(variant))
    ticks = 6000
    err, differ = lockstep(arm, py, c, bench_trajectory(arm, ticks, seed=3), ticks,
                            inject_faults)
    assert differ == []
    assert err.max() <= TOL
    assert_same_counters(py, c)
    assert py.stats.failures["injected"] > 0 and py.stats.failures["nonfinite_input"] > 0
    if variant != "keep-no-screening":
        assert py.stats.failures.get("max_iter", 0) > 0  # the carried-over iterate was used
    if variant == "joint-bounds-shift":  # all three levels, the envelope rows checked in C too
        assert py.stats.screened > 0 and py.stats.boxed > 0


@needs_cc
@pytest.mark.parametrize(("binding", "python_offset"),
                         [("ctypes", False), ("ctypes", True), ("extension", True)])
def test_every_binding_matches_python(arm, built, binding, python_offset):
    """The ctypes fallback, and the offset evaluated in Python (``extra_inputs``), give the
    same ticks as the compiled binding with the offset in C: faults, bounds, all levels."""
    variant = "joint-bounds-shift"
    py = RecedingHorizonMPC(arm, MPCSettings(**VARIANTS[variant]))
    c = twin(py, built(variant), binding=binding,
             extra_inputs=py.offset if python_offset else None)
    assert (c.binding, c.extra_source) == (binding, "python" if python_offset else "fk")

    ticks = 3000
    err, differ = lockstep(arm, py, c, bench_trajectory(arm, ticks, seed=3), ticks,
                            inject_faults)
    assert differ == []
    assert err.max() <= TOL
    assert_same_counters(py, c)


class Lockstep:
    """Closed-loop controller: runs both, applies Python's torque, injects faults into both."""

    def __init__(self, py, c, tau_max):
        self.py, self.c, self.tau_max = py, c, tau_max
        self.k = 0
        self.err: list[float] = []
        self.differ: list[tuple] = []
        self.stats = py.stats

    def step(self, x, ref):
        k = self.k
        self.k += 1
        if k % 1500 == 700:  # a burst longer than plan_fallback_ticks: plan, then LQ
            self.py.force_failures(25)
            self.c.force_failures(25)
        if k % 2500 == 1300:  # a corrupted state estimate: plan (then zero if it lasts)
            x = np.full_like(x, np.nan)
        if k % 3100 == 2000:
            ref = ref.copy()
            ref[7, 2] = np.inf
        tp = self.py.step(x, ref)
        tc = self.c.step(x, ref)
        self.err.append(float(np.max(np.abs(tc - tp) / self.tau_max)))
        if (self.py.stats.status, self.py.stats.source) != (self.c.status, self.c.source):
            self.differ.append((k, self.py.stats.status, self.c.status))
        self.stats = self.py.stats
        return tp


@needs_cc
def test_closed_loop_with_faults_matches_python(arm, built):
    """20 000 ticks of the Pinocchio closed loop (predictor, sensor) with injected faults."""
    from rhmpc.experiment import RunConfig, build_run
    from sim.loop import run_closed_loop

    config = RunConfig().replace(**{"loop.duration": 10.0, "loop.settling": 1.0})
    run = build_run(config)
    py = run.controller
    lock = Lockstep(py, twin(py, built("default")), np.asarray(run.robot.torque_limit))
    run_closed_loop(run.robot, run.arm, lock, run.reference, run.truth, run.center, run.stream,
                    config.loop, plant_settings=config.plant, mismatch=config.mismatch,
                    observer_settings=config.observer)
    assert lock.k == 20_000
    assert lock.differ == []
    assert max(lock.err) <= TOL
    assert_same_counters(py, lock.c)
    fb = py.stats.fallbacks
    assert fb["plan"] > 0 and fb["lq"] > 0 and fb["zero"] == 0
    assert py.stats.failures["nonfinite_input"] > 0


@needs_cc
def test_two_controllers_on_one_library_do_not_share_the_solver(arm, built):
    """OSQP's generated workspace is static: a second instance must get its own copy."""
    lib = built("default")
    py = RecedingHorizonMPC(arm, MPCSettings())
    first = twin(py, lib)
    traj = bench_trajectory(arm, 2200)
    x = np.zeros(arm.nx)
    second = None
    for k in range(2200):
        ref = traj[k + 1:k + 51]
        if k == 990:
            second = twin(py, lib)  # its init must not reset the first one's solver
        if second is not None:
            second.step(x + 1e-3, ref[::-1])
        tp, tc = py.step(x, ref), first.step(x, ref)
        assert np.max(np.abs(tc - tp) / np.asarray(arm.torque_limit)) <= TOL, k
        x = arm.A @ x + arm.B @ tp
    assert second.library != first.library


@needs_cc
def test_library_uses_no_heap_io_or_locks(built):
    """The static library's external symbols: only the monotonic clock, memset/memcpy/memmove
    (the level-2 active set's shifts) and libm (sin and cos, or their sincos: the output offset's
    forward kinematics)."""
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("nm (binutils) not found")
    static = built("default").parent / "librhmpc.a"
    undefined = subprocess.run([nm, "-u", static], capture_output=True, text=True, check=True)
    defined = subprocess.run([nm, "--defined-only", static], capture_output=True, text=True,
                             check=True)
    und = {ln.split()[-1] for ln in undefined.stdout.splitlines() if ln.strip() and ":" not in ln}
    dfn = {ln.split()[-1] for ln in defined.stdout.splitlines() if len(ln.split()) == 3}
    external = und - dfn
    assert external <= {"clock_gettime", "memset", "memcpy", "memmove", "_GLOBAL_OFFSET_TABLE_",
                        "fabs", "sqrt", "sin", "cos", "sincos", "__stack_chk_fail"}, external
    assert "clock_gettime" in external  # the tick times itself


@needs_cc
def test_binding_counters_and_u_prev(arm, built):
    py = RecedingHorizonMPC(arm)
    c = twin(py, built("default"), dims=(50, 6, 3, 3))
    np.testing.assert_allclose(c.u_max, py.u_max, rtol=0, atol=0)
    assert c.stats.ticks == 0 and c.source == "none"
    c.u_prev = np.array([100.0, 0.0, 0.0])  # clipped to u_max inside C, as in Python
    assert c.u_prev[0] == c.u_max[0]
    with pytest.raises(ValueError, match="u_prev"):
        c.u_prev = np.array([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="expected"):
        twin(py, built("default"), dims=(40, 6, 3, 3))
    with pytest.raises(ValueError, match="step expects"):
        c.step(np.zeros(5), np.zeros((50, 3)))


@needs_cc
@pytest.mark.parametrize("robot", ["phantom", "finger_edu"])
def test_offset_in_c_is_pinocchios_forward_kinematics(robot, cache):
    """rhmpc_offset against RecedingHorizonMPC.offset at random states: the forward kinematics
    (RX/RY/RZ and, on finger_edu, a revolute-unaligned joint) to the bit; C x + y0 summed in
    column order, which numpy's BLAS may round differently (measured ≤ 1.1e-16 m)."""
    import ctypes

    import pinocchio as pin

    arm = linearize(load_robot(robot))
    mpc = RecedingHorizonMPC(arm)
    lib = ctypes.CDLL(str(build_cached(mpc, robot, cache)))
    assert lib.rhmpc_extra_source() == 1  # RHMPC_EXTRA_FK
    lib.rhmpc_offset.argtypes = (ctypes.c_void_p, ctypes.c_void_p)
    model, data, frame = arm.robot.model, arm.robot.create_data(), arm.robot.ee_frame_id
    rng = np.random.default_rng(1)
    d = np.zeros(3)
    for _ in range(2000):
        x = rng.normal(scale=[0.3] * 3 + [1.0] * 3) * 10 ** rng.uniform(-6, 0)
        lib.rhmpc_offset(x.ctypes.data, d.ctypes.data)
        pin.forwardKinematics(model, data, arm.q0 + x[:3])
        p = pin.updateFramePlacement(model, data, frame).translation
        lin = [sum((float(arm.C[a, c]) * float(x[c]) for c in range(arm.nx)), 0.0)
               for a in range(3)]
        np.testing.assert_array_equal(d, p - (np.array(lin) + arm.y0))
        np.testing.assert_allclose(d, mpc.offset(x), rtol=0, atol=1e-15)


def _strided(a: np.ndarray) -> np.ndarray:
    """``a``'s values in a view every other element of a wider buffer (not contiguous)."""
    wide = np.zeros((*a.shape[:-1], 2 * a.shape[-1]))
    wide[..., ::2] = a
    return wide[..., ::2]


def _read_only(a: np.ndarray) -> np.ndarray:
    a = a.copy()
    a.setflags(write=False)
    return a


@needs_cc
def test_step_takes_any_float_array_and_returns_a_new_one(arm, built):
    """Lists, strided views, Fortran order, read-only arrays: the same torque as C-contiguous
    float64 arrays, to the bit; each call returns a new array that the caller owns."""
    py = RecedingHorizonMPC(arm)
    a, b = twin(py, built("default")), twin(py, built("default"))
    forms = (lambda v: v.tolist(), _strided, np.asfortranarray, _read_only)
    traj = bench_trajectory(arm, 40)
    x = np.zeros(arm.nx)
    taus = []
    for k in range(40):
        ref = traj[k + 1:k + 51]
        form = forms[k % len(forms)]
        taus.append(a.step(x, ref))
        np.testing.assert_array_equal(b.step(form(x), form(ref)), taus[-1])
        x = arm.A @ x + arm.B @ taus[-1]
    assert not np.shares_memory(taus[-1], taus[-2])
    taus[-1][:] = 99.0
    assert np.all(a.u_prev != 99.0)
    a.reset()
    np.testing.assert_array_equal(a.u_prev, np.zeros(arm.nu))


@needs_cc
def test_without_the_extension_the_binding_is_ctypes_and_says_why(built, monkeypatch):
    """No compiler for the extension: "auto" falls back to ctypes with a one-line reason;
    "extension" raises it."""
    from rhmpc.control.export import ToolchainError, extension

    lib = built("default")
    extension.load.cache_clear()
    try:
        monkeypatch.setenv("PATH", "")
        monkeypatch.delenv("CC", raising=False)
        c = CController(lib)
        assert c.binding == "ctypes"
        assert len(c.binding_note.splitlines()) == 1 and "compiler" in c.binding_note
        with pytest.raises(ToolchainError, match="compiler"):
            CController(lib, binding="extension")
    finally:
        monkeypatch.undo()
        extension.load.cache_clear()
    assert CController(lib).binding == "extension"


@needs_cc
@pytest.mark.parametrize("source", ["caller", "zero"])
def test_extra_inputs_from_the_caller_or_zero(arm, cache, monkeypatch, source):
    """Kinematics the generator does not know: the caller gives the offset (a note says so);
    without offset correction the extra inputs stay zero. Both match Python tick for tick."""
    from rhmpc.control.export import extra_source, generate

    settings = MPCSettings(offset_correction=source != "zero")
    if source == "caller":
        monkeypatch.setattr(generate, "_FK_JOINTS", {})
    py = RecedingHorizonMPC(arm, settings)
    assert extra_source(py) == source
    lib = build_cached(py, "phantom", cache)
    if source == "caller":
        with pytest.raises(ValueError, match="give extra_inputs"):
            CController(lib)
        info = export_controller(py, cache / "caller-src", robot="phantom")
        assert any("forward kinematics" in n for n in info.notes)
    c = CController(lib, extra_inputs=py.offset if source == "caller" else None)
    assert c.extra_source == ("python" if source == "caller" else "zero")
    ticks = 2000
    err, differ = lockstep(arm, py, c, bench_trajectory(arm, ticks), ticks)
    assert differ == [] and err.max() <= TOL


def test_export_refuses_what_the_embedded_code_cannot_do(arm, tmp_path):
    for bad, match in (({"adaptive_rho": True}, "adaptive_rho"), ({"polish": True}, "polish")):
        mpc = RecedingHorizonMPC(arm, MPCSettings(**bad))
        with pytest.raises(ExportError, match=match):
            export_controller(mpc, tmp_path / "out", robot="phantom")
    # A wall-clock limit cannot be generated (no timer in OSQP's embedded code): said, not hidden
    mpc = RecedingHorizonMPC(arm, MPCSettings(time_limit=2e-4))
    info = export_controller(mpc, tmp_path / "out", robot="phantom")
    assert len(info.notes) == 1 and "time_limit" in info.notes[0]
    assert "Not exported: time_limit" in (tmp_path / "out" / "rhmpc.h").read_text()


def test_export_writes_the_controllers_numbers(arm, tmp_path):
    """The const arrays are the CondensedQP's, to the last bit (repr round-trips)."""
    mpc = RecedingHorizonMPC(arm, dataclasses.replace(MPCSettings(), rate_weight=0.2))
    info = export_controller(mpc, tmp_path / "out", robot="phantom")
    text = (info.outdir / "rhmpc_data.c").read_text()
    body = text.split("rhmpc_minimiser[")[1].split("{")[1].split("}")[0]
    values = np.array([float(v) for v in body.replace("\n", " ").split(",")])
    np.testing.assert_array_equal(values, mpc.qp.minimiser.ravel())
    header = (info.outdir / "rhmpc.h").read_text()
    assert "#define RHMPC_N 50" in header and f"#define RHMPC_NPAR {mpc.qp.npar} " in header
    assert (info.outdir / "CMakeLists.txt").is_file()
    assert (info.outdir / "osqp" / "rhmpc_osqp_workspace.c").is_file()
    assert not (info.outdir / "osqp" / "emosqp.c").exists()  # OSQP's example main (printf)


def test_cli_export_with_config(tmp_path, capsys):
    cfg = tmp_path / "run.toml"
    cfg.write_text("robot = \"finger_edu\"\n[mpc]\nhorizon = 40\n"
                   "blocks = [2, 2, 3, 3, 4, 5, 6, 7, 8]\n[loop]\nhorizon = 40\n")
    assert main(["export", "--config", str(cfg), str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "finger_edu" in out and "cmake -S" in out
    assert "#define RHMPC_N 40" in (tmp_path / "out" / "rhmpc.h").read_text()
    (tmp_path / "file").write_text("")
    assert main(["export", str(tmp_path / "file")]) == 2
    assert "not a directory" in capsys.readouterr().err


def test_cli_without_toolchain_says_so_and_exits_2(monkeypatch, capsys):
    monkeypatch.setenv("PATH", "")
    monkeypatch.delenv("CC", raising=False)
    for argv in (["bench", "--controller", "c", "--ticks", "10"],
                 ["simulate", "--controller", "c", "--duration", "1"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "cmake" in err, err


STATIC_MAIN = r"""
#include <stdio.h>
#include "rhmpc.h"
/* 200 ticks at rest, reference 3 mm away along x (bounds bind at first), no Python. */
int main(void) {
  static rhmpc_t ctl;
  double x[RHMPC_NX] = {0}, ref[RHMPC_NY * RHMPC_N], tau[RHMPC_NU];
  for (int k = 0; k < RHMPC_N; ++k)
    for (int a = 0; a < RHMPC_NY; ++a) ref[RHMPC_NY * k + a] = rhmpc_y0[a] + (a == 0 ? 3e-3 : 0);
  rhmpc_init(&ctl);
  for (int k = 0; k < 200; ++k) rhmpc_tick(&ctl, x, ref, NULL, tau);
  printf("%.17g %.17g %.17g %lld %lld\n", tau[0], tau[1], tau[2], ctl.ticks, ctl.screened);
  return 0;
}
"""


@needs_cc
def test_static_library_links_into_a_c_program(arm, built, tmp_path):
    """A plain C program against rhmpc.h and librhmpc.a gives Python's torque."""
    build = built("default").parent
    src = next(build.parent.glob("src"))
    (tmp_path / "main.c").write_text(STATIC_MAIN)
    cc = next(c for c in ("cc", "gcc", "clang") if shutil.which(c))
    exe = tmp_path / "main"
    subprocess.run([cc, "-O2", "-I", str(src), str(tmp_path / "main.c"),
                    str(build / "librhmpc.a"), "-lm", "-o", str(exe)], check=True)
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()
    py = RecedingHorizonMPC(arm, MPCSettings())
    ref = np.tile(arm.y0 + np.array([3e-3, 0.0, 0.0]), (py.N, 1))
    for _ in range(200):
        tau = py.step(np.zeros(arm.nx), ref)
    np.testing.assert_allclose([float(v) for v in out[:3]], tau, rtol=0,
                               atol=TOL * np.max(arm.torque_limit))
    assert int(out[3]) == 200 and int(out[4]) == py.stats.screened
    assert int(out[4]) < 200  # OSQP ran (a bound was active on some ticks)


@needs_cc
def test_cli_simulate_with_the_c_controller(monkeypatch, cache, capsys):
    """`rhmpc simulate --controller c`: the same run as the Python controller's."""
    import json

    monkeypatch.setenv("RHMPC_CACHE_DIR", str(cache))
    docs = {}
    for impl in ("python", "c"):
        assert main(["simulate", "--controller", impl, "--duration", "1", "--json"]) == 0
        docs[impl] = json.loads(capsys.readouterr().out)
    assert docs["c"]["implementation"] == "c"
    for key in ("rms_error_mm", "max_error_mm", "rms_effort_mNm"):
        # The two agree per tick to ~5e-11 τ_max (the lockstep tests); in closed loop those
        # rounding differences reach the 1-s run's metrics at 1e-9–1e-8 relative (measured
        # 3.5e-9). They stay there until one puts a joint on the other side of an encoder
        # step, which changes a longer run at the 1e-3 level: 1e-6 here.
        assert docs["c"][key] == pytest.approx(docs["python"][key], rel=1e-6), key
    assert docs["c"]["controller"]["ticks"] == 2000


@needs_cc
def test_level_2_matches_python_under_heavy_saturation(arm, cache):
    """Far references from moving states saturate many of the 30 block torques: level 2's
    second phase (the dual active set, up to 16 solves) runs in C as in Python: the same
    level, the same number of solves and the same torque (1e-6 τ_max) on every tick."""
    py = RecedingHorizonMPC(arm, MPCSettings(joint_envelope=False))
    c = twin(py, build_cached(py, "phantom", cache))
    rng = np.random.default_rng(0)
    tau_max = np.asarray(arm.torque_limit)
    solves = []
    for _ in range(300):
        x = np.zeros(arm.nx)
        x[3:] = rng.normal(scale=0.3, size=3)
        ref = np.tile(arm.y0 + rng.normal(scale=rng.uniform(1e-3, 2e-2), size=3), (py.N, 1))
        py.reset()
        c.reset()
        tp, tc = py.step(x, ref), c.step(x, ref)
        assert (py.stats.level, py.stats.box_iterations) == (c.level, c.stats.box_iterations)
        assert np.max(np.abs(tp - tc) / tau_max) <= TOL
        if py.stats.level == 2:
            solves.append(py.stats.box_iterations)
    assert len(solves) > 30 and max(solves) >= 10  # the dual active set was needed and ran


@needs_cc
@pytest.mark.parametrize(("changes", "planned"), [
    ({}, True), ({"loop.pipelined_refresh": False, "loop.downsample": 10}, True),
    ({"predictor": "one-step", "loop.downsample": 4, "loop.predictor_clock": "downsample"},
     True),
    ({"loop.downsample": 7}, False)])  # the sensor's clock (257 Hz): the slices from Python
def test_compiled_ticks_run_the_python_loops_ticks_to_the_bit(monkeypatch, cache, changes,
                                                              planned):
    """The control ticks between two refresh slices in one C call (``loop.compiled_ticks``)
    call the same C functions in the same order as the loop's Python path: the same run to
    the bit, with a u_{−1} handed over to the first tick, the yardstick on the same inputs,
    and chunks of 600 ticks (u_{−1} and the yardstick's phase carried across them). With the
    compiled refresh the slices run from the C ticks too (``OpenLoop.plan``), each on its own
    tick: the same run again, and so without them (the slices called from Python between the
    C calls)."""
    from rhmpc.control.compiled_reference import CompiledReference
    from rhmpc.experiment import RunConfig, build_run
    from sim.loop import run_closed_loop
    from sim.loop.ticks import compiled_ticks
    from sim.plant.tick import make_tick

    monkeypatch.setenv("RHMPC_CACHE_DIR", str(cache))
    runs = {}
    for way in ("planned", "segments", "python"):
        config = RunConfig().replace(**{"loop.duration": 2.0, "loop.settling": 0.5,
                                        "loop.compiled_ticks": way != "python", **changes})
        run = build_run(config, "c")
        assert run.refresh == "compiled"
        run.controller.u_prev = np.array([0.02, -0.01, 0.005])
        seen = []
        with monkeypatch.context() as patch:
            if way == "segments":
                patch.delattr(CompiledReference, "slices")
            result = run_closed_loop(
                run.robot, run.arm, run.controller, run.reference, run.truth, run.center,
                run.stream, config.loop, plant_settings=config.plant,
                mismatch=config.mismatch, observer_settings=config.observer, chunk_ticks=600,
                yardstick=lambda x, r, u, seen=seen: seen.append((x.copy(), r.copy(),
                                                                  u.copy())))
        runs[way] = (result, run.controller.stats, seen, dict(run.reference.predictor.counts),
                     run.reference.predictor.forecast_error_rms)
    slow, slow_stats, slow_seen, slow_counts, slow_rms = runs["python"]
    assert runs["planned"][0].tick_loop == ("compiled with the refresh" if planned
                                            else "compiled")
    assert runs["segments"][0].tick_loop == "compiled"
    assert slow.tick_loop == "python (loop.compiled_ticks = false)"
    for fast, fast_stats, fast_seen, counts, rms in (runs["planned"], runs["segments"]):
        for name in ("ee", "reference0", "tau_mpc", "tau_command", "tau"):
            np.testing.assert_array_equal(fast.trace[name], slow.trace[name], err_msg=name)
        assert fast.tracking == slow.tracking
        np.testing.assert_array_equal(fast.horizon_error, slow.horizon_error)
        assert counts == slow_counts and counts["updates"] > 100
        np.testing.assert_array_equal(rms, slow_rms)
        timing = {"parts_ns", "solve_time"}
        assert {k: v for k, v in dataclasses.asdict(fast_stats).items() if k not in timing} == \
            {k: v for k, v in dataclasses.asdict(slow_stats).items() if k not in timing}
        assert fast_stats.ticks == 4000
        timed = len(range(YARDSTICK_PHASE, 4000, YARDSTICK_EVERY))  # three calls each
        assert len(fast_seen) == len(slow_seen) == 3 * timed
        for a, b in zip(fast_seen, slow_seen, strict=True):
            for u, v in zip(a, b, strict=True):
                np.testing.assert_array_equal(u, v)
        # every slice was charged to a tick: five parts, each about once a refresh
        assert fast.tick_parts_us["predictor_update"]["p50"] == 0.0
        assert fast.tick_parts_us["interpolation"]["max"] > 0.0
    # a controller of other sizes than the loop's is left to the Python path, which says so
    side = make_tick(run.robot, run.arm, config.loop.Ts, config.plant, config.mismatch,
                     config.observer)
    other = dataclasses.replace(config.loop, horizon=20, compiled_ticks=True)
    ticks, loop = compiled_ticks(run.controller, side, other)
    assert ticks is None and "(N, nx, nu, ny) (50, 6, 3, 3)" in loop
