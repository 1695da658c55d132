"""`rhmpc bench`: the benchmark runs, reports what the issue asks for, and agrees with DAQP.

Timing is reported, never asserted.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rhmpc.bench.report import format_table
from rhmpc.bench.ticks import heart_like_reference, run_bench
from rhmpc.cli import main
from rhmpc.control.export import missing_toolchain
from rhmpc.control.settings import MPCSettings


def test_heart_like_reference_amplitude_and_jumps():
    rng = np.random.default_rng(0)
    center = np.array([0.1, 0.0, -0.1])
    n = round(6.0 / 0.5e-3)  # one breathing period ≈ 5.9 s
    p = heart_like_reference(n, 0.5e-3, rng, center, breathing_pp=0.0)
    assert p.shape == (n, 3)
    np.testing.assert_allclose(np.ptp(p[:, 0]), 8e-3, rtol=1e-6)
    jumped = heart_like_reference(n, 0.5e-3, np.random.default_rng(0), center, breathing_pp=0.0,
                                  jump=2e-3, jump_every=1000)
    steps = np.linalg.norm(np.diff(jumped - p, axis=0), axis=1)
    assert np.isclose(steps.max(), 2e-3)


@pytest.mark.slow
def test_run_bench_reports_the_issue_fields():
    r = run_bench(ticks=400, warmup=50, seed=1, jump_every=150)
    for key in ("tick_us", "osqp_tick_us", "solve_us", "gain_tick_us", "exact_tick_us",
                "iterations"):
        row = r[key]
        assert 0 < row["p50"] <= row["p99"] <= row["max"], key
        assert row["mean"] <= row["max"], key
    # Both levels of the screening cascade ran: the unconstrained minimiser, and the torque-box
    # QP on the saturated ticks (the jumps saturate); levels 1 and 2 are exact: their u0 is
    # DAQP's to rounding (measured ≈ 1e-12 τ_max; bound 1e-8).
    assert 0 < r["screened_ticks"] == r["levels"]["1"] < r["ticks"]
    assert r["levels"]["2"] > 0 and sum(r["levels"].values()) == r["ticks"]
    assert r["box_iterations"]["max"] <= 3 + 30  # the cap: PDAS's solves and nz (30)
    assert r["u0_error_cascade_max_frac"] <= 1e-8
    # OSQP on every tick: at least one iteration, never more than the cap.
    assert 1 <= r["iterations"]["p50"] and r["iterations"]["max"] <= MPCSettings().max_iter
    # The ratios are those of the reported percentiles (same run, same ticks).
    for key, ref in (("ratio_tick_to_gain", "gain_tick_us"), ("ratio_tick_to_exact",
                                                              "exact_tick_us")):
        assert r[key]["p50"] == pytest.approx(r["tick_us"]["p50"] / r[ref]["p50"], rel=1e-12)
    assert r["ticks"] == 400 and r["robot"] == "phantom"
    assert set(r["fallbacks"]) == {"plan", "lq", "brake", "zero"}
    assert r["active_bound_ticks"] > 0  # the jumps saturate the torque
    assert r["u0_error_max_frac"] <= 0.01  # within 1 % of τ_max of the exact solve, every tick
    assert r["exact_failures"] == 0
    assert "MPC tick" in format_table(r)
    json.dumps(r)


@pytest.mark.slow
def test_cli_bench_json_and_table(capsys):
    assert main(["bench", "--ticks", "150", "--warmup", "10", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert {"tick_us", "solve_us", "iterations", "fallbacks", "u0_error_max_frac",
            "gain_tick_us", "exact_tick_us"} <= set(r)
    assert main(["bench", "--ticks", "100", "--warmup", "0", "--robot", "finger_edu",
                 "--host-stalls", "0.05"]) == 0
    out = capsys.readouterr().out
    assert "p99" in out and "host: a busy loop of 0.05 s stalled" in out
    assert main(["bench", "--ticks", "0"]) == 2
    assert "--ticks" in capsys.readouterr().err
    assert main(["bench", "--host-stalls", "-2"]) == 2
    assert "--host-stalls" in capsys.readouterr().err


@pytest.mark.skipif(missing_toolchain() is not None, reason=missing_toolchain() or "")
@pytest.mark.slow
def test_run_bench_with_the_exported_controller():
    """`--controller c`: the whole exported controller in a loop of its own, every tick timed
    inside C (refresh ticks included) beside the gain tick of the same run."""
    r = run_bench(ticks=1500, warmup=50, seed=1, jump_every=400, controller="c")
    t, g = r["exported_tick_us"], r["exported_tick_g"]
    assert 0 < t["p50"] <= t["p99"] <= t["max"]
    assert g["p99"] == pytest.approx(t["p99"] / r["exported_gain_tick_us"]["p50"])
    assert r["controller"] == "c" and r["exported_refresh_tick_us"]["p50"] > 0
    assert r["exported_levels"]["1"] > 0 and r["exported_levels"]["0"] == 0
    # every failed solve is counted and served by a fallback
    assert sum(r["exported_fallbacks"].values()) == sum(r["exported_failures"].values())
    assert 0 < r["c_tick_us"]["p50"] <= r["c_tick_us"]["p99"]
    text = format_table(r)
    assert "exported controller" in text and "refresh ticks" in text
    json.dumps(r)


@pytest.mark.skipif(missing_toolchain() is not None, reason=missing_toolchain() or "")
@pytest.mark.slow
def test_run_bench_with_readings_that_come_late():
    """`--reading-delay 40`: every step fuses the reading of 40 ticks before and predicts
    forward. The bench's plant is the controller's model, so that the prediction from a late
    reading is the state itself: the loop tracks as the on-time one does (to rounding). The
    option needs the exported controller."""
    late = run_bench(ticks=1500, warmup=100, seed=1, jump_every=400, controller="c",
                     reading_delay=40)
    on_time = run_bench(ticks=1500, warmup=100, seed=1, jump_every=400, controller="c")
    assert late["exported_reading_delay_ticks"] == 40
    assert 0 < late["exported_tick_us"]["p50"] <= late["exported_tick_us"]["p99"]
    assert late["exported_tracking_rms_mm"] == pytest.approx(
        on_time["exported_tracking_rms_mm"], rel=1e-9)
    assert main(["bench", "--reading-delay", "4"]) == 2
