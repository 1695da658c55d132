"""How close any predictor can come to the exact reference when the stream holds white noise.

The exact reference hands the MPC the recorded stream's future, its white range error included,
and the error is scored against that same stream: the robot follows noise it was told of in
advance. No causal predictor can know the future of a white sequence. The bound here is a
reference that knows the stream's whole future below a cut-off f_c and nothing above it:

    r_k = (h_fc ⋆ y)(k Ts),   |H_fc(f)|² = 1 / (1 + (f / f_c)^16),

a 4th-order Butterworth low-pass run forward and backward (zero phase), gaps bridged linearly
first. It is better than any predictor on everything below f_c; Tuna et al. §III-B has the POI
motion within 0.14 mm RMS of its content up to 26 Hz, so what lies above 26 Hz is the sensor's.

Runs the main job (``rhmpc simulate`` defaults, seed 7, as the ``simulate-generalized``
target) and Table I's setting (``--preset tuna2013``, seed 3) on each replica, with the exact
reference, the bound at f_c = 26, 40 and 60 Hz, and the two RLS predictors. Writes
``docs/results/causal_bound``.

    python benchmarks/causal_bound.py [--quick]
"""

from __future__ import annotations

import argparse

import _results as R
import numpy as np
from scipy.signal import butter, sosfiltfilt

from rhmpc.cli.presets import PRESETS
from rhmpc.experiment import RunConfig
from rhmpc.experiment.assembly import build_controller, build_run
from rhmpc.paper.tables import COLUMNS
from rhmpc.sim.heart.analysis import fill_gaps
from rhmpc.sim.loop import run_closed_loop
from rhmpc.sim.loop.exact import ArrayTruth, ExactReference

#: Cut-off frequencies of the bound [Hz].
CUTOFFS = (26.0, 40.0, 60.0)
#: Each row's reference: a predictor's name, or ("bound", f_c).
ROWS = ("exact", *(("bound", f) for f in CUTOFFS), "one-step", "generalized")


def lowpassed(truth, fc: float, Ts: float) -> ArrayTruth:
    """The centred truth zero-phase low-passed at ``fc`` [Hz], NaN bridged linearly first."""
    x = fill_gaps(np.arange(truth.n_ticks), truth.window(0, truth.n_ticks))
    sos = butter(4, fc, fs=1.0 / Ts, output="sos")
    return ArrayTruth(sosfiltfilt(sos, x, axis=0), truth.center)


def tracking(config: RunConfig, fc: float | None) -> dict:
    """The run's tracking metrics; with ``fc``, the bound's reference instead of the run's (the
    same controller around it)."""
    run = build_run(config)
    controller = run.controller
    if fc is not None:
        reference = ExactReference(lowpassed(run.truth, fc, config.loop.Ts), config.mpc.horizon)
        reference.place(run.anchor)
        controller = build_controller(config, run.robot, run.arm, reference)
    result = run_closed_loop(run.plant, controller, run.truth, run.stream, config.loop,
                             run.clock, anchor=run.anchor, robot=run.robot)
    return result.tracking


def settings(duration: float) -> dict[str, RunConfig]:
    """Column → its configuration (the predictor set per row)."""
    main = {"main job": RunConfig(seed=7).replace(**{"loop.duration": duration})}
    table1 = {s: RunConfig(scenario=s, seed=3).replace(
        **PRESETS["tuna2013"], **{"loop.duration": duration,
                                  "loop.settling": min(20.0, duration / 3)})
        for s in COLUMNS}
    return {**main, **table1}


def label(row) -> str:
    return f"exact below {row[1]:g} Hz" if isinstance(row, tuple) else row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10-s runs, main job only")
    a = ap.parse_args()
    duration = 10.0 if a.quick else 60.0
    columns = settings(duration)
    if a.quick:
        columns = {"main job": columns["main job"]}
    data = {}
    for col, config in columns.items():
        for row in ROWS:
            fc = row[1] if isinstance(row, tuple) else None
            cfg = config.replace(predictor="exact" if fc else row)
            t = tracking(cfg, fc)
            data.setdefault(col, {})[label(row)] = {
                "rms_error_mm": t["rms_error_mm"], "rms_effort_mNm": t["rms_effort_mNm"]}
            print(f"{col} {label(row)}: {t['rms_error_mm']:.4f} mm", flush=True)
    header = ["reference", *[c if c == "main job" else f"I: {c}" for c in columns]]
    rms = [[label(r), *[R.fmt(data[c][label(r)]["rms_error_mm"], 3) for c in columns]]
           for r in ROWS]
    ratio = [[label(r), *[R.fmt(data[c][label(r)]["rms_error_mm"]
                                / data[c]["exact"]["rms_error_mm"], 2) for c in columns]]
             for r in ROWS]
    R.write("causal_bound", "The exact reference against references that cannot know the noise",
            {"duration_s": duration, "cutoffs_hz": list(CUTOFFS), "runs": data},
            {"bound-rms|RMS position error against the recorded stream [mm]": R.table(header, rms),
             "bound-ratio|÷ the exact reference's": R.table(header, ratio)}, a.quick)


if __name__ == "__main__":
    main()
