"""The exported controller's every tick, and the Python simulation's own speed.

The real-time budget belongs to the controller that is deployed: the C that ``rhmpc export``
generates (the predictor's refresh, the gate and the interpolation, the observer, the MPC with
its cascade and fallbacks, the cancellation). ``rhmpc bench --controller c --json`` runs it in a
closed loop of its own on a heart-like reference and times every tick inside C, refresh ticks
included, beside the gain tick g of the same loop. Two references:

* the bench's own, which jumps by 2 mm every 1000 ticks so that the torque bounds bind;
* ``--jump-mm 1000``, jumps of 1 m: a reference the arm cannot reach, which keeps the solver and
  the fallbacks busy (the worst case the tick must still fit);
* the first with ``--reading-delay 40``: each step takes the encoders' reading of 40 ticks
  before (20 ms, the observer's window), which it fuses there and carries forward with 40
  predictions (the most a step of a robot behind a middleware does).

For each: p50, p99 and max in µs and in g, the refresh ticks alone, the ticks per level of the
screening cascade, the fallbacks and the solver's failures, and the host's stalls measured right
after (``--host-stalls``: a loop that only reads the clock; no tick that a stall lands in can be
shorter). Where no C compiler is found, this part is skipped and the record says why.

Then the simulation's speed on the main job, ``rhmpc simulate --predictor generalized
--duration 60 --seed 2 --json``, on the ideal plant and on the hardware-like one (a ``--set`` of
each value of ``rhmpc.experiment.presets.HARDWARE_PLANT``, the hardware preset's plant, all else
the same): the wall time per simulated second and the tick's parts (the controller's step, the
reference's refreshes) in the gain tick of that run, and the plant's own tick (``encoders()``
and ``step(τ)``, the dynamics kernel and what composes it)
timed here beside g. That is how fast a study runs, not a real-time figure: the Python
controller is the reference implementation. Writes ``docs/results/exported_tick``.

    python benchmarks/exported_tick.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R

from rhmpc.experiment.presets import HARDWARE_PLANT

#: The references of the exported controller's runs: label → ``rhmpc bench`` options.
REFERENCES = {"2-mm jumps": (), "1-m jumps (unreachable)": ("--jump-mm", "1000"),
              "2-mm jumps, readings 20 ms late": ("--reading-delay", "40")}
#: The fallbacks of the MPC, in the order it tries them.
FALLBACKS = ("plan", "lq", "brake", "zero")


def cli(*args: str) -> tuple[dict | None, str]:
    """``rhmpc ARGS --json``'s document and its command line, or None and why it failed."""
    cmd = [sys.executable, "-m", "rhmpc.cli", *args, "--json"]
    command = " ".join(["rhmpc", *cmd[3:]])
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        print(f"{command}: {run.stderr.strip()}", file=sys.stderr)
        return None, (run.stderr.strip().splitlines() or ["no message"])[-1]
    return json.loads(run.stdout), command


def exported(ticks: int, stalls: float) -> tuple[dict, str | None]:
    """The exported controller's runs (label → their figures), or why there are none."""
    from rhmpc.compiled import compiler

    if compiler() is None:
        return {}, "no C compiler (cc or gcc, or $CC) was found"
    runs = {}
    for label, options in REFERENCES.items():
        doc, command = cli("bench", "--controller", "c", "--ticks", str(ticks),
                           "--host-stalls", f"{stalls:g}", *options)
        if doc is None:
            return {}, f"`rhmpc bench --controller c` failed: {command}"
        runs[label] = {"command": command,
                       **{k: v for k, v in doc.items() if k.startswith("exported_")},
                       "host_stalls": doc["host_stalls"]}
    return runs, None


#: The plants of the simulation's runs: label → ``rhmpc simulate`` options.
PLANTS = {"ideal": (), "hardware-like": tuple(
    item for key, value in HARDWARE_PLANT.items()
    for item in ("--set", f"{key}={json.dumps(value)}"))}


def simulation(duration: float) -> tuple[dict | None, str]:
    """The main job's documents on each plant (label → its speed and the tick's parts)."""
    out = {}
    for label, options in PLANTS.items():
        doc, command = cli("simulate", "--predictor", "generalized", "--duration",
                           f"{duration:g}", "--seed", "2", *options)
        if doc is None:
            return None, command
        keep = ("gain_tick_us", "tick_us", "tick_parts_us", "tick_ratio_to_gain",
                "tick_parts_ratio_to_gain", "wall_per_simulated_s_g", "tick_per_simulated_s_g",
                "real_time_factor", "wall_s", "rms_error_mm")
        out[label] = {"command": command, "duration_s": duration,
                      **{k: doc[k] for k in keep}, "plant_tick": plant_tick(label)}
    return out, ""


def plant_tick(label: str, ticks: int = 4000) -> dict:
    """The plant's tick alone (``encoders()`` then ``step(τ)``, τ holding the arm against
    gravity plus a 10-Hz swing) and the gain tick g, interleaved in this process: p50 [µs] of
    each and their ratio."""
    import time

    import numpy as np
    import pinocchio as pin

    from rhmpc.experiment import RunConfig, build_run
    from rhmpc.timing.yardstick import GainTick

    config = RunConfig(predictor="generalized", seed=2)
    if label != "ideal":
        config = config.replace(**HARDWARE_PLANT)
    run = build_run(config)
    plant, gain = run.plant, GainTick(run.controller.mpc)
    hold = pin.computeGeneralizedGravity(run.robot.model, run.robot.create_data(), run.robot.q0)
    x, ref, u = np.zeros(6), np.tile(run.arm.y0, (run.controller.N, 1)), np.zeros(3)
    plant_ns, gain_ns, clock = [], [], time.perf_counter_ns
    for i in range(ticks):
        tau = hold + 0.02 * np.sin(2 * np.pi * 10 * i * run.arm.Ts)
        t0 = clock()
        plant.encoders()
        plant.step(tau)
        t1 = clock()
        gain(x, ref, u)
        plant_ns.append(t1 - t0)
        gain_ns.append(clock() - t1)
    p, g = np.median(plant_ns) / 1e3, np.median(gain_ns) / 1e3
    return {"p50_us": p, "gain_tick_us": g, "ratio_to_gain": p / g}


def exported_tables(runs: dict) -> dict[str, str]:
    """The exported controller's tables: its tick, and its cascade levels and fallbacks."""
    ticks = []
    for label, d in runs.items():
        us, g = d["exported_tick_us"], d["exported_tick_g"]
        refresh, stalls = d["exported_refresh_tick_us"] or {}, d["host_stalls"]
        ticks.append([label, R.fmt(d["exported_gain_tick_us"]["p50"], 2),
                      R.fmt(us["p50"], 2), R.fmt(us["p99"], 2), R.fmt(us["max"], 1),
                      R.fmt(g["p50"], 2), R.fmt(g["p99"], 1), R.fmt(g["max"], 0),
                      R.fmt(refresh.get("p99"), 2), R.fmt(stalls["longest_us"], 0)])
    levels = []
    for label, d in runs.items():
        count, level_us = d["exported_levels"], d["exported_level_tick_us"]
        cells = [f"{count[v]} ({R.fmt(level_us[v]['p99'], 1)})" if v in level_us
                 else str(count[v]) for v in ("1", "2", "3")]
        fallbacks = d["exported_fallbacks"]
        failures = ", ".join(f"{k} {n}" for k, n in sorted(d["exported_failures"].items()))
        levels.append([label, *cells, *(str(fallbacks.get(k, 0)) for k in FALLBACKS),
                       failures or "none"])
    return {
        "exported|The exported controller, every tick timed inside C (refresh ticks included)":
            R.table(["reference", "g [µs]", "p50 [µs]", "p99 [µs]", "max [µs]", "p50 [g]",
                     "p99 [g]", "max [g]", "refresh ticks p99 [µs]",
                     "longest host stall [µs]"], ticks),
        "exported-levels|Its ticks per level of the screening cascade (p99 [µs]), fallbacks "
        "and the solver's failures":
            R.table(["reference", "level 1", "level 2", "level 3",
                     *(f"fallback: {k}" for k in FALLBACKS), "solver failures"], levels)}


def simulation_table(runs: dict) -> str:
    """The simulation's speed on each plant, its tick's parts and the plant's tick."""
    rows = []
    for label, d in runs.items():
        tick, parts, plant = d["tick_us"], d["tick_parts_us"], d["plant_tick"]
        rows.append([label, R.fmt(d["duration_s"], 0), R.fmt(d["gain_tick_us"]["p50"], 2),
                     R.fmt(d["wall_per_simulated_s_g"], 0), R.fmt(d["real_time_factor"], 1),
                     R.fmt(tick["p50"], 1), R.fmt(parts["step"]["p99"], 1),
                     R.fmt(parts["refresh"]["p99"], 1), R.fmt(plant["p50_us"], 1),
                     R.fmt(plant["ratio_to_gain"], 1)])
    return R.table(
        ["plant", "simulated [s]", "g [µs]", "wall per simulated s [g]", "× real time",
         "tick p50 [µs]", "step p99 [µs]", "refresh p99 [µs]", "plant tick p50 [µs]",
         "plant tick p50 [g]"], rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="2000 ticks and a 10-s simulation instead of 20000 and 60 s")
    a = ap.parse_args()
    ticks, stalls, duration = (2000, 1.0, 10.0) if a.quick else (20000, 4.0, 60.0)
    runs, skipped = exported(ticks, stalls)
    sim, command = simulation(duration)
    if sim is None:
        sys.exit(f"rhmpc simulate failed: {command}")
    tables = exported_tables(runs) if runs else {}
    tables["simulation|The simulation's speed on the main job (not a real-time figure)"] \
        = simulation_table(sim)
    simulation_note = (
        "The simulation's rows are a study's run (the generalized predictor on fixed-a2-top, "
        "PHANToM, sonomicrometer) on each plant: its step is the controller's library "
        "(observer, MPC, cancellation), its refresh the reference's (the gate and the "
        "interpolation in the library, the predictor in Python); on the ideal plant the ticks "
        "between two refreshes run in C (`plant_run`), on the hardware-like one a tick at a "
        "time from Python. The plant's tick (encoders and step, the dynamics kernel and what "
        "composes it) is timed beside g in the benchmark's own process.")
    if runs:
        predictor = next(iter(runs.values()))["exported_predictor"]
        notes = ("The exported controller runs in a closed loop of its own on the linear "
                 f"model, with the {predictor} predictor refreshed from a sample of the "
                 "reference every `loop.downsample` ticks; its g is the gain tick timed beside "
                 "it in the same loop. A level's cell is its number of ticks, and in "
                 "parentheses their p99. The host's longest stall is measured right after the "
                 "ticks, in the same process: a tick's maximum near it is the host's, not the "
                 "controller's. With the readings 20 ms late, each step fuses the reading of "
                 "40 ticks before and predicts 40 ticks forward (the observer's window). "
                 + simulation_note)
    else:
        notes = f"The exported controller was not timed here: {skipped}. " + simulation_note
    R.write("exported_tick", "The exported controller's tick, and the simulation's speed",
            {"ticks": ticks, "host_stall_s": stalls, "exported": runs,
             "exported_skipped": skipped, "simulation": sim}, tables, a.quick, notes=notes)


if __name__ == "__main__":
    main()
