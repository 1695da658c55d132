"""The MPC alone: ``rhmpc bench`` (tick percentiles in gain ticks, screening levels, accuracy).

Runs ``rhmpc bench --controller c --json``: the controller library's MPC beside the gain tick
g, OSQP on every
tick and an exact DAQP solve, and the whole exported controller of ``rhmpc export`` in a loop of
its own on the same reference, every tick timed inside C (``exported_tick_us``, against the gain
tick of that loop: ``exported_tick_g``). Where no C compiler is found, ``--controller python``
alone, and the record says why. Writes ``docs/results/mpc_timing``.

    python benchmarks/mpc_timing.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R


def bench(ticks: int, controller: str) -> tuple[dict | None, str]:
    """``rhmpc bench``'s document (None if it failed) and its command, or why it failed."""
    cmd = [sys.executable, "-m", "rhmpc.cli", "bench", "--ticks", str(ticks), "--json",
           "--controller", controller]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        why = (run.stderr.strip().splitlines() or ["no message"])[-1]
        print(f"bench --controller {controller}: {run.stderr.strip()}", file=sys.stderr)
        return None, why
    doc = json.loads(run.stdout)
    doc["command"] = " ".join(["rhmpc", *cmd[3:]])
    return doc, doc["command"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2000 ticks instead of 20000")
    a = ap.parse_args()
    ticks = 2000 if a.quick else 20000
    doc, c_note = bench(ticks, "c")
    exported = doc is not None
    if doc is None:
        doc, why = bench(ticks, "python")
        if doc is None:
            sys.exit(f"rhmpc bench failed: {why}")
    g = doc["gain_tick_us"]

    def row(label: str, us: dict, digits: int = 1) -> list[str]:
        return [label, R.fmt(us["p50"], digits), R.fmt(us["p99"], digits),
                R.fmt(us["p50"] / g["p50"], 2), R.fmt(us["p99"] / g["p50"], 2)]

    rows = [row("MPC tick (screening cascade)", doc["tick_us"]),
            row("MPC tick, OSQP every tick", doc["osqp_tick_us"]),
            row("exact tick, DAQP", doc["exact_tick_us"])]
    if exported:
        us, ratio = doc["exported_tick_us"], doc["exported_tick_g"]
        rows.insert(1, ["exported controller, every tick (inside C)", R.fmt(us["p50"], 2),
                        R.fmt(us["p99"], 2), R.fmt(ratio["p50"], 2), R.fmt(ratio["p99"], 2)])
    rows.append(["gain tick g", R.fmt(g["p50"], 1), R.fmt(g["p99"], 1), R.fmt(1.0, 2), "—"])
    t1 = R.table(["tick", "p50 [µs]", "p99 [µs]", "p50 [g]", "p99 [g]"], rows)
    levels = doc["levels"]
    t2 = R.table(["level", "ticks", "what settles it"], [
        ["1", R.fmt(levels["1"]), "unconstrained minimiser, every row holds"],
        ["2", R.fmt(levels["2"]), "torque-box QP by active set"],
        ["3", R.fmt(levels["3"]), "the solver (OSQP)"]])
    acc = R.table(["u₀ error against DAQP", "max [fraction of τ_max]"], [
        ["levels 1–2", R.fmt(doc["u0_error_cascade_max_frac"], 1, sci=True)],
        ["every tick, the cascade", R.fmt(doc["u0_error_max_frac"], 1, sci=True)],
        ["OSQP every tick", R.fmt(doc["osqp_u0_error_max_frac"], 1, sci=True)]])
    tables = {"ticks|Tick time (same run, same gain tick)": t1,
              "levels|Screening cascade: ticks per level": t2, "Accuracy": acc}
    notes = ("The reference moves like a heart and jumps by 2 mm every 1000 ticks so that the "
             "torque bounds bind. Absolute microseconds depend on the machine and its load; "
             "the ratios to the gain tick g carry over.")
    if exported:
        notes += (" The exported controller's row is every tick of the whole controller of "
                  "`rhmpc export` (the predictor's refresh on its ticks, the observer, the MPC, "
                  "the cancellation) in a loop of its own on the same reference, timed inside C "
                  "and stated in the gain tick of that loop (`benchmarks/exported_tick.py` "
                  "measures it in full).")
    else:
        notes += f" The exported controller was not timed: {c_note}."
    R.write("mpc_timing", "The MPC alone (rhmpc bench)", {
        "ticks": ticks, "bench": doc, "exported": exported,
        "exported_unavailable": None if exported else c_note}, tables, a.quick, notes=notes)


if __name__ == "__main__":
    main()
