"""`rhmpc bench`: the benchmark runs, reports what the issue asks for, and agrees with DAQP.

Timing is reported, never asserted.
"""

from __future__ import annotations

import json

import numpy as np

from rhmpc.cli import main
from rhmpc.studies.bench import format_table, heart_like_reference, run_bench


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


def test_run_bench_reports_the_issue_fields():
    r = run_bench(ticks=400, warmup=50, seed=1, jump_every=150)
    for key in ("tick_us", "solve_us", "gain_tick_us", "exact_tick_us", "reference_us",
                "update_us", "output_us", "iterations"):
        assert {"p50", "p99", "max"} <= set(r[key]), key
        assert r[key]["p50"] > 0
    assert r["ticks"] == 400 and r["robot"] == "phantom"
    assert set(r["fallbacks"]) == {"plan", "lq", "zero"}
    assert r["active_bound_ticks"] > 0  # the jumps saturate the torque
    assert r["u0_error_max_frac"] <= 0.01  # within 1 % of τ_max of the exact solve, every tick
    assert r["exact_failures"] == 0
    assert "MPC tick" in format_table(r)
    json.dumps(r)


def test_cli_bench_json_and_table(capsys):
    assert main(["bench", "--ticks", "150", "--warmup", "10", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert {"tick_us", "solve_us", "iterations", "fallbacks", "u0_error_max_frac",
            "gain_tick_us", "exact_tick_us"} <= set(r)
    assert main(["bench", "--ticks", "100", "--warmup", "0", "--robot", "finger_edu"]) == 0
    assert "p99" in capsys.readouterr().out
    assert main(["bench", "--ticks", "0"]) == 2
    assert "--ticks" in capsys.readouterr().err
