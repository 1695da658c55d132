"""Faults injected into the main job's closed loop: what each did, and what the controller did.

``rhmpc simulate`` with its defaults (``generalized`` on ``fixed-a2-top``, physical
sonomicrometer, PHANToM, 30 s, seed 0), run once clean, once per fault and once with the four
together (``--fault``, :mod:`rhmpc.sim.sensors.faults`), each after the outlier gate's calibration:

- a sensor that freezes for 0.3 s, a burst of missing samples for 0.5 s, a persistent 5-mm
  jump of the stream (the truth does not move), all encoders stuck for 0.2 s, and for 20 ms.

For each: the RMS error over the run (after settling), the largest error during the fault and
in the second after it, what was counted (samples missing or rejected by the gate, gate
unlocks, encoder ticks held, the MPC's fallbacks by kind) and whether the joint angles stayed
within the robot's joint and speed limits. Writes ``docs/results/faults``.

    python benchmarks/faults.py [--quick]
"""

from __future__ import annotations

import argparse

import _results as R

from rhmpc.experiment import RunConfig, run_experiment

#: Each fault's one-line form, by its start [s] (full run; --quick shifts them, see ``plan``).
FAULTS = ("freeze@{0}:0.3", "nan@{1}:0.5", "jump@{2}:5mm", "stick@{3}:0.2")
#: A stick the controller rides through, beside the one it does not.
SHORT_STICK = "stick@{3}:0.02"
#: The counts of a fault's record shown in the tables, with their headers.
COUNTS = {"missing": "missing", "outliers_rejected": "rejected", "gate_unlocked": "unlocks",
          "encoder_held_ticks": "encoder ticks held"}
FALLBACKS = ("plan", "lq", "brake", "zero")


def plan(quick: bool) -> tuple[float, tuple[str, ...], str]:
    """(duration [s], the four faults, the short stick): every fault after the gate's 10 s of
    calibration, the stick last (what follows it is a wreck when the arm runs away)."""
    duration, starts = (20.0, (11, 13, 15, 17.5)) if quick else (30.0, (14, 17, 20, 24))
    return duration, tuple(f.format(*starts) for f in FAULTS), SHORT_STICK.format(*starts)


def measure(duration: float, events: tuple[str, ...]) -> dict:
    """The run's score, its fault records, envelope and controller counters."""
    config = RunConfig().replace(**{"loop.duration": duration, "faults.events": events})
    _, doc = run_experiment(config)
    return {"faults": list(events), "rms_error_mm": doc["rms_error_mm"],
            "max_error_mm": doc["max_error_mm"], "joint_envelope": doc["joint_envelope"],
            "fault_reports": doc.get("faults", []), "predictor_counts": doc["predictor_counts"],
            "fallbacks": doc["controller"]["fallbacks"], "failures": doc["controller"]["failures"]}


def counted(report: dict, key: str) -> int:
    return sum((report[w] or {}).get("counts", {}).get(key, 0) for w in ("during", "after"))


def fallbacks(report: dict) -> str:
    kinds = [f"{k} {counted(report, 'fallback_' + k)}" for k in FALLBACKS
             if counted(report, "fallback_" + k)]
    return ", ".join(kinds) or "0"


def held(report: dict) -> str:
    ok = all((report[w] or {}).get("envelope_held", True) for w in ("during", "after"))
    return "yes" if ok else "**no**"


def row(report: dict) -> list[str]:
    """A fault's cells: form, window, errors, counts, fallbacks, envelope."""
    after = report["after"]
    return [f"`{report['fault']}`", f"{R.fmt(report['start_s'], 2)}–{R.fmt(report['end_s'], 2)}",
            R.fmt(report["during"]["max_error_mm"], 3),
            R.fmt(after["max_error_mm"], 3) if after else "to the end",
            *[str(counted(report, k)) for k in COUNTS], fallbacks(report), held(report)]


HEADER = ["fault", "window [s]", "max error during [mm]", "max error 1 s after [mm]",
          *COUNTS.values(), "MPC fallbacks", "envelope held"]
#: The single-fault table's column of each run's score, after the window's.
RMS = "RMS error of the run [mm]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20-s runs instead of 30-s")
    a = ap.parse_args()
    duration, faults, short = plan(a.quick)
    runs = {"none": measure(duration, ())}
    for spec in (*faults, short):
        runs[spec] = measure(duration, (spec,))
        print(f"{spec}: RMS {runs[spec]['rms_error_mm']:.3f} mm", flush=True)
    runs["all"] = measure(duration, faults)
    clean = runs["none"]
    single = [["none", "—", R.fmt(clean["rms_error_mm"], 3), *["—"] * (len(HEADER) - 2)]]
    for spec in (*faults, short):
        cells = row(runs[spec]["fault_reports"][0])
        single.append([*cells[:2], R.fmt(runs[spec]["rms_error_mm"], 3), *cells[2:]])
    together = [row(r) for r in runs["all"]["fault_reports"]]
    everything = (f"faults-all|The four in one run (RMS error of the run "
                  f"{R.fmt(runs['all']['rms_error_mm'], 3)} mm)")
    R.write("faults", "Faults injected into the main job's closed loop", {
        "scenario": "fixed-a2-top", "predictor": "generalized", "sensor": "sonomicrometry",
        "seed": 0, "duration_s": duration,
        "settling_s": RunConfig().replace(**{"loop.duration": duration}).loop.settling_s,
        "runs": runs},
        {"faults-single|Each fault alone": R.table([*HEADER[:2], RMS, *HEADER[2:]], single),
         everything: R.table(HEADER, together)}, a.quick,
        notes="Counts over the fault and the second after it; *missing* leaves out the samples "
              "the gate rejected. The envelope held when every joint angle stayed within the "
              "robot's joint limits (coupled ones included) and every joint's speed within its "
              "limit.")


if __name__ == "__main__":
    main()
