"""The README's headline: each predictor in closed loop on the main job, and the README figure.

``rhmpc simulate --predictor NAME`` on ``fixed-a2-top`` (physical sonomicrometer, PHANToM,
defaults), seed 0: RMS and max tracking error, RMS MPC effort, the p99 of the simulation's tick
(the Python controller's step and its reference's refreshes) in gain ticks, QP fallbacks.
Writes ``docs/results/headline.json``/``.md`` and the tracking figure
``docs/_static/tracking-run.png`` (the generalized predictor's run).

    python benchmarks/headline.py [--quick]
"""

from __future__ import annotations

import argparse

import _results as R

from rhmpc.experiment import RunConfig, run_experiment

PREDICTORS = ("exact", "one-step", "generalized", "ekf", "hold")
FIGURE = R.ROOT / "docs" / "_static" / "tracking-run.png"


def figure(result, path) -> None:
    """POI motion per axis and the tracking error over the last seconds of the run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    t = result.time
    keep = t >= t[-1] - 3.0
    poi = 1e3 * (result.poi - np.nanmean(result.poi, axis=0))
    err = 1e3 * np.linalg.norm(result.error, axis=1)
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(8, 4.2), sharex=True, constrained_layout=True,
                                 gridspec_kw={"height_ratios": [3, 2]})
    for k, name in enumerate("xyz"):
        a0.plot(t[keep], poi[keep, k], lw=0.9, label=f"POI {name}")
    a0.set(ylabel="position [mm]",
           title="Tracking a point on the beating heart (generalized RLS forecast, 2 kHz MPC)")
    a0.legend(ncol=3, fontsize=8, loc="upper right")
    a1.plot(t[keep], err[keep], color="C3", lw=0.8)
    a1.set(xlabel="time [s]", ylabel="‖tool − POI‖ [mm]")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20-s runs instead of 60-s")
    a = ap.parse_args()
    duration = 20.0 if a.quick else 60.0
    settling = 12.0 if a.quick else 20.0
    rows, data = [], []
    for name in PREDICTORS:
        config = RunConfig(predictor=name, scenario="fixed-a2-top", seed=0).replace(
            **{"loop.duration": duration, "loop.settling": settling})
        result, doc = run_experiment(config, gain_tick=True)
        if name == "generalized":
            figure(result, FIGURE)
        d = {"predictor": name, "rms_error_mm": doc["rms_error_mm"],
             "max_error_mm": doc["max_error_mm"], "rms_effort_mNm": doc["rms_effort_mNm"],
             "tick_p99_in_g": doc["tick_ratio_to_gain"]["p99"], "fallbacks": doc["fallbacks"],
             "real_time_factor": doc.get("real_time_factor")}
        data.append(d)
        rows.append([f"`{name}`", R.fmt(d["rms_error_mm"]), R.fmt(d["max_error_mm"]),
                     R.fmt(d["rms_effort_mNm"], 1), R.fmt(d["tick_p99_in_g"], 1),
                     R.fmt(d["fallbacks"])])
    tab = R.table(["predictor", "RMS error [mm]", "max error [mm]", "RMS effort [mN·m]",
                   "simulation tick p99 [g]", "QP fallbacks"], rows)
    R.write("headline", "Closed loop on the main job", {
        "scenario": "fixed-a2-top", "sensor": "sonomicrometry", "seed": 0,
        "duration_s": duration, "settling_s": settling, "rows": data}, {"": tab}, a.quick,
        notes="A simulation runs the controller to deploy: one library, the C of `rhmpc "
              "export`, bound to Python; the run's predictor feeds it from Python. The "
              "benchmarks page gives its tick.")


if __name__ == "__main__":
    main()
