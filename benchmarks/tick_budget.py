"""The whole control tick of the main job, and the simulation's speed, in gain ticks g.

``rhmpc simulate --predictor generalized --duration 60 --seed 2 --json`` with the Python
controller and with ``--controller c`` (where a C toolchain and cmake are), two runs each, in
fresh processes; once with the C controller's ticks called one at a time from Python
(``--set loop.compiled_ticks=false``), for the cost of the interpreter between them; and once
with the Python controller and the predictor's Python refresh (``--set
loop.compiled_refresh=false``), for what the compiled refresh saves. For each
run: the tick's percentiles in multiples of the gain tick g timed in the same run, the same
without the refresh slices (sense + controller + actuate: the tick with the predictor in a task
of its own), the p99 of each part, and the wall time per simulated second beside the ticks' own
work per simulated second (the mean tick × 2000 ticks), which no simulator of this controller
can undercut. After each run, in the same process, a busy loop as long as a 60-s run's loop
(``--host-stalls``) measures what the host takes from it: the floor under the tick's maximum.
Writes ``docs/results/tick_budget``.

    python benchmarks/tick_budget.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R

PARTS = ("sense", "controller", "actuate", "predictor_update", "predictor_learn", "forecast",
         "interpolation", "scoring")


def simulate(duration: float, controller: str, stalls: float, *extra: str) -> dict | None:
    """One main-job run's document, or None where the controller cannot be built."""
    cmd = [sys.executable, "-m", "rhmpc.cli", "simulate", "--predictor", "generalized",
           "--duration", f"{duration:g}", "--seed", "2", "--json", "--controller", controller,
           "--host-stalls", f"{stalls:g}", *extra]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        print(f"simulate --controller {controller}: {run.stderr.strip()}", file=sys.stderr)
        return None
    doc = json.loads(run.stdout)
    keep = ("gain_tick_us", "tick_us", "tick_ratio_to_gain", "control_tick_ratio_to_gain",
            "tick_parts_ratio_to_gain", "wall_per_simulated_s_g", "tick_per_simulated_s_g",
            "real_time_factor", "rms_error_mm", "host_stalls", "tick_loop", "refresh")
    return {"command": " ".join(["rhmpc", *cmd[3:]]), **{k: doc[k] for k in keep}}


def tick_row(label: str, d: dict) -> list[str]:
    r, c = d["tick_ratio_to_gain"], d["control_tick_ratio_to_gain"]
    h = d["host_stalls"]
    return [label, R.fmt(d["gain_tick_us"]["p50"], 2), R.fmt(r["p50"], 1), R.fmt(r["p99"], 1),
            R.fmt(r["p999"], 1), R.fmt(r["max"], 0), R.fmt(c["p99"], 1), R.fmt(c["max"], 0),
            str(h["over_50_g"]), R.fmt(h["longest_g"], 0)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10-s runs instead of 60-s")
    a = ap.parse_args()
    duration, stalls = (10.0, 1.0) if a.quick else (60.0, 4.0)
    runs = {}
    for controller in ("python", "c"):
        for k in (1, 2):
            doc = simulate(duration, controller, stalls)
            if doc is not None:
                runs[f"{controller} {k}"] = doc
    for label, controller, setting in (
            ("c, ticks from Python", "c", "loop.compiled_ticks=false"),
            ("python, Python refresh", "python", "loop.compiled_refresh=false")):
        doc = simulate(duration, controller, stalls, "--set", setting)
        if doc is not None:
            runs[label] = doc
    ticks = R.table(
        ["run", "g [µs]", "p50 [g]", "p99 [g]", "p99.9 [g]", "max [g]",
         "p99 without slices [g]", "max without slices [g]",
         f"host stalls > 50 g in {stalls:g} s", "longest host stall [g]"],
        [tick_row(label, d) for label, d in runs.items()])
    parts = R.table(
        ["run", *(p.replace("_", " ") for p in PARTS)],
        [[label, *(R.fmt(d["tick_parts_ratio_to_gain"][p]["p99"], 1) for p in PARTS)]
         for label, d in runs.items()])
    speed = R.table(
        ["run", "wall per simulated s [g]", "ticks per simulated s [g]", "real time ×"],
        [[label, R.fmt(d["wall_per_simulated_s_g"], 0), R.fmt(d["tick_per_simulated_s_g"], 0),
          R.fmt(d["real_time_factor"], 1)] for label, d in runs.items()])
    R.write("tick_budget", "The whole tick of the main job",
            {"duration_s": duration, "host_stall_s": stalls, "runs": runs},
            {"ticks|The whole tick, in gain ticks of the same run": ticks,
             "parts|Its parts, p99 [g]": parts,
             "speed|The simulation's speed": speed}, a.quick,
            notes="Each run is a fresh process on the main job (the generalized predictor on "
                  "fixed-a2-top, PHANToM, sonomicrometer). A tick's parts do not add up to "
                  "its p99: the refresh slices fall on different ticks. The ticks' own work "
                  "per simulated second is the mean tick times the control rate: the "
                  "controller's real computation, which a simulator of it cannot undercut. "
                  "The host's stalls are those of a loop that does nothing but read the clock "
                  "(`rhmpc simulate --host-stalls`), right after the run in the same process: "
                  "a tick that one of them lands in lasts at least as long. The predictor's "
                  "refresh is compiled (`loop.compiled_refresh`) but in the run marked "
                  "\"Python refresh\"; the C controller's runs call its ticks and the refresh "
                  "slices from C (`loop.compiled_ticks`), but the one marked \"ticks from "
                  "Python\", which calls both from Python.")


if __name__ == "__main__":
    main()
