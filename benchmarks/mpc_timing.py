"""The MPC alone: ``rhmpc bench`` (tick percentiles in gain ticks, screening levels, accuracy).

Runs ``rhmpc bench --json`` with the Python controller, and with ``--controller c`` when a C
compiler and cmake are there. Writes ``docs/results/mpc_timing``.

    python benchmarks/mpc_timing.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R


def bench(ticks: int, controller: str) -> dict | None:
    cmd = [sys.executable, "-m", "rhmpc.cli", "bench", "--ticks", str(ticks), "--json",
           "--controller", controller]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        print(f"bench --controller {controller}: {run.stderr.strip()}", file=sys.stderr)
        return None
    doc = json.loads(run.stdout)
    doc["command"] = " ".join(["rhmpc", *cmd[3:]])
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2000 ticks instead of 20000")
    a = ap.parse_args()
    ticks = 2000 if a.quick else 20000
    py = bench(ticks, "python")
    c = bench(ticks, "c")
    doc = c if c is not None else py
    g = doc["gain_tick_us"]
    def row(label: str, us: dict, digits: int = 1) -> list[str]:
        return [label, R.fmt(us["p50"], digits), R.fmt(us["p99"], digits),
                R.fmt(us["p50"] / g["p50"], 2), R.fmt(us["p99"] / g["p50"], 2)]

    rows = [row("MPC tick (screening cascade)", doc["tick_us"]),
            row("MPC tick, OSQP every tick", doc["osqp_tick_us"]),
            row("exact tick, DAQP", doc["exact_tick_us"])]
    if c is not None:
        rows.insert(1, row("C tick, inside C", c["c_tick_us"], 2))
    rows.append(["gain tick g", R.fmt(g["p50"], 1), R.fmt(g["p99"], 1), R.fmt(1.0, 2), "—"])
    t1 = R.table(["tick", "p50 [µs]", "p99 [µs]", "p50 [g]", "p99 [g]"], rows)
    levels = doc["levels"]
    t2 = R.table(["level", "ticks", "what settles it"], [
        ["1", R.fmt(levels.get("1", levels.get(1))), "unconstrained minimiser, every row holds"],
        ["2", R.fmt(levels.get("2", levels.get(2))), "torque-box QP by active set"],
        ["3", R.fmt(levels.get("3", levels.get(3))), "the solver (OSQP)"]])
    acc = R.table(["u₀ error against DAQP", "max [fraction of τ_max]"], [
        ["levels 1–2", R.fmt(doc["u0_error_cascade_max_frac"], 1, sci=True)],
        ["OSQP every tick", R.fmt(doc["u0_error_max_frac"], 1, sci=True)]])
    tables = {"ticks|Tick time (same run, same gain tick)": t1,
              "levels|Screening cascade: ticks per level": t2, "Accuracy": acc}
    if c is not None:
        tables["c|C against Python"] = R.table(["max ‖τ_C − τ_Python‖ / τ_max", "mismatched ticks"],
                                             [[R.fmt(c["c_vs_python_max_frac"], 1, sci=True),
                                               R.fmt(c["c_mismatched_ticks"])]])
    R.write("mpc_timing", "The MPC alone (rhmpc bench)", {
        "ticks": ticks, "python": py, "c": c}, tables, a.quick,
        notes="The reference moves like a heart and jumps by 2 mm every 1000 ticks so that the "
              "torque bounds bind. Absolute microseconds depend on the machine and its load; "
              "the ratios to the gain tick g carry over.")


if __name__ == "__main__":
    main()
