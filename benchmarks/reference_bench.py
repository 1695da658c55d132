"""Open-loop reference bench: the closed loop's heart → sensor → predictor → reference chain alone.

Steps 1–3 of the closed loop (``sim.loop.closed_loop``) do not depend on the robot, so the
reference the MPC would track is
reproduced exactly without the arm: the run is built by ``rhmpc.experiment.build_run`` from the
same settings as ``rhmpc simulate`` (scenario, ``--rr``, seed, sensor, outlier gate, guard), and
only the predictor's refreshes are driven. Scored from ``settling`` on, against the recorded
stream (the paper's ground truth, as ``simulate``): the reference's error at 25 ms (the last
horizon point) — RMS, max — and the *episodes*: ticks where it exceeds 1 mm.

    .venv/bin/python benchmarks/reference_bench.py --predictor generalized --seeds 0,3,7 \
        [--scenarios fixed-a2-top,...] [--set predictor_settings.KEY=JSON ...] [--duration 60]
"""

from __future__ import annotations

import argparse
import json
import math
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rhmpc.studies.paper import COLUMNS

SCENARIOS = COLUMNS  # Tuna et al. Tables I–III


def refreshes(changes: dict):
    """Build the run of ``changes`` (``RunConfig.replace`` keys) and drive its open-loop part:
    yields ``(tick, run, cursor)`` after each refresh's forecast, before the next update (the
    order of ``sim.loop``'s pipelined refresh)."""
    from rhmpc.experiment import RunConfig, build_run
    from sim.loop.closed_loop import OpenLoop

    cfg = RunConfig().replace(**changes)
    run, loop = build_run(cfg), cfg.loop
    ref, ds, n = run.reference, loop.downsample, loop.ticks
    open_loop = OpenLoop(ref, run.stream, run.center, loop, hold=None)
    open_loop.finish()  # the first refresh's update, learning and forecast (ticks −3 … −1)
    for i in range(0, n, ds):
        ref.forecast()
        yield i, run, open_loop.cursor
        if i + ds - 1 < n:
            open_loop.update(i + ds - 1)


def one(job):
    scenario, seed, predictor, sets, duration, rr = job
    from rhmpc.cli.simulate import parse_value

    changes = {"scenario": scenario, "seed": seed, "predictor": predictor, "rr": rr,
               "loop.duration": duration, "loop.settling": 10.0}
    for item in sets:
        key, _, value = item.partition("=")
        changes[key.strip()] = parse_value(value.strip())
    errs = []
    for i, run, _ in refreshes(changes):
        loop = run.config.loop
        ds, N, n = loop.downsample, loop.horizon, loop.ticks
        if i < int(loop.settling / loop.Ts):
            continue
        period = run.reference.horizons(i, min(ds, n - i))
        if period is None:  # before the first sample
            continue
        truth = run.truth.window(i + 1, i + len(period) + N)
        for k, h in enumerate(period):
            errs.append(np.linalg.norm(h[N - 1] - truth[k + N - 1]))
    e = 1e3 * np.asarray(errs)
    e = e[np.isfinite(e)]  # the recorded stream has gaps (missing samples)
    counts = dict(run.reference.predictor.counts)
    return scenario, seed, {
        "rms": float(math.sqrt(np.mean(e**2))), "max": float(e.max()),
        "episodes_ms": float(np.sum(e > 1.0) * loop.Ts * 1e3),
        "counts": {k: v for k, v in counts.items() if k not in ("updates",)},
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--predictor", default="generalized")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--seeds", default="0,3,7")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--rr", default=None)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    jobs = [(s, int(seed), a.predictor, a.set, a.duration, a.rr)
            for seed in a.seeds.split(",") for s in a.scenarios.split(",")]
    with ProcessPoolExecutor(a.jobs) as ex:
        res = list(ex.map(one, jobs))
    if a.json:
        print(json.dumps(res, indent=1))
        return
    print(f"{a.predictor} set={a.set} rr={a.rr}: 25-ms reference error vs recorded [mm]")
    print(f"{'scenario':<16}{'seed':>5}{'rms':>8}{'max':>8}{'>1mm ms':>9}  counts")
    for scenario, seed, r in res:
        print(f"{scenario:<16}{seed:>5}{r['rms']:>8.3f}{r['max']:>8.2f}{r['episodes_ms']:>9.1f}  "
              f"{r['counts']}")
    rms = [r["rms"] for *_, r in res]
    print(f"mean rms {np.mean(rms):.4f}  worst max {max(r['max'] for *_, r in res):.2f}  "
          f"episodes {sum(r['episodes_ms'] for *_, r in res):.1f} ms")


if __name__ == "__main__":
    main()
