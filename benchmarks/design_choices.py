"""The measured side of the design decisions (docs/design/decisions/): each choice against its
alternative, on the same run.

* outlier gate: the floor calibrated on the data (``auto``) against the instrument's accuracy
  as a fixed floor (0.25 mm) and no gate, on the main job (sonomicrometer, cycle slips);
* predictor clock: a 25-Hz recording with the predictor on each raw sample (``sensor``)
  against every 15 ticks on the 2-kHz stream (``downsample``);
* the exported controller: ``--controller c`` (the C that ``rhmpc export`` generates) against
  the Python controller it is generated from (where a C compiler is found).

    python benchmarks/design_choices.py [--quick]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import _results as R
import numpy as np

from rhmpc.experiment import RunConfig, run_experiment

METRICS = ("rms_error_mm", "max_error_mm", "rms_effort_mNm")


def run(config: RunConfig, implementation: str = "python") -> dict:
    _, doc = run_experiment(config, implementation=implementation)
    return doc


def metrics_row(label: str, doc: dict, extra=()) -> list[str]:
    return [label, R.fmt(doc["rms_error_mm"]), R.fmt(doc["max_error_mm"]),
            R.fmt(doc["rms_effort_mNm"], 1), R.fmt(doc["fallbacks"]), *extra]


def rel_diff(a: dict, b: dict) -> float:
    return max(abs(a[k] - b[k]) / abs(b[k]) for k in METRICS)


def gate(duration: float) -> tuple[dict, str]:
    base = RunConfig(predictor="generalized", scenario="fixed-a2-top", seed=0).replace(
        **{"loop.duration": duration, "loop.settling": min(20.0, duration / 3)})
    runs = {"auto (calibrated on the data)": run(base),
            "fixed 0.25 mm (the instrument's accuracy)": run(base.replace(
                **{"reference.outlier_gate": 0.25e-3})),
            "none": run(base.replace(**{"reference.outlier_gate": 0.0}))}
    rows = []
    for label, d in runs.items():
        g = d["outlier_gate"]
        rows.append(metrics_row(label, d, [R.fmt(g.get("floor_mm"), 3),
                                           R.fmt(g["outliers_rejected"]), R.fmt(g["retracted"]),
                                           R.fmt(g["repaired"])]))
    tab = R.table(["gate", "RMS [mm]", "max [mm]", "effort [mN·m]", "fallbacks", "floor [mm]",
                   "rejected", "retracted", "repaired"], rows)
    return {k: {m: v[m] for m in (*METRICS, "fallbacks", "outlier_gate")}
            for k, v in runs.items()}, tab


def clock(duration: float) -> tuple[dict, str]:
    from rhmpc.sim.heart import make_scenario
    from rhmpc.sim.recordings.text import save_recording

    rng = np.random.default_rng(1)
    length = duration + 2.0
    scenario = make_scenario("fixed-a2-top", rng, duration=length)
    t = np.arange(0.0, length, 1 / 25)
    z = scenario.source.position(t) + 1e-4 * rng.standard_normal((t.size, 3))
    path = save_recording(Path(tempfile.mkdtemp()) / "rec25.csv", t, z)
    base = RunConfig(predictor="one-step", data=str(path), sensor="recorded", seed=0).replace(
        **{"loop.duration": duration, "loop.settling": min(20.0, duration / 3)})
    runs = {mode: run(base.replace(**{"loop.predictor_clock": mode}))
            for mode in ("sensor", "downsample")}
    tab = R.table(["predictor clock", "RMS [mm]", "max [mm]", "effort [mN·m]", "fallbacks"],
                  [metrics_row(f"`{m}`", d) for m, d in runs.items()])
    return {k: {m: v[m] for m in (*METRICS, "fallbacks", "predictor_clock")}
            for k, v in runs.items()}, tab


def controller(duration: float) -> tuple[dict | None, str | None]:
    base = RunConfig(predictor="generalized", scenario="fixed-a2-top", seed=0).replace(
        **{"loop.duration": duration, "loop.settling": min(20.0, duration / 3)})
    try:
        c = run(base, "c")
    except Exception as exc:  # no toolchain: the record says so
        print(f"exported controller unavailable: {exc}")
        return None, None
    py = run(base)
    diff = rel_diff(c, py)
    tab = R.table(["controller", "RMS [mm]", "max [mm]", "effort [mN·m]",
                   "largest relative difference"], [
        [*metrics_row("C (`--controller c`)", c)[:4], R.fmt(diff, 1, sci=True)],
        [*metrics_row("Python", py)[:4], "reference"]])
    return {"c": {m: c[m] for m in METRICS}, "python": {m: py[m] for m in METRICS},
            "relative_difference": diff}, tab


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20-s runs instead of 60-s")
    a = ap.parse_args()
    duration = 20.0 if a.quick else 60.0
    data, tables = {}, {}
    for name, fn, caption in (
            ("gate", lambda d: gate(max(d, 60.0)), "gate|Outlier gate, main job (60 s)"),
            ("clock", clock, "clock|Predictor clock, a 25-Hz recording (one-step)"),
            ("controller", controller,
             "controller|The exported controller (C) against the Python one, main job")):
        d, tab = fn(duration)
        data[name] = d
        if tab is not None:
            tables[caption] = tab
    R.write("design_choices", "Design choices, measured", {"duration_s": duration, **data},
            tables, a.quick)


if __name__ == "__main__":
    main()
