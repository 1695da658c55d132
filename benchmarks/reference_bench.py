"""Open-loop reference bench: the closed loop's heart → sensor → reference chain alone.

The samples that refresh the reference, and the points it makes, do not depend on the robot, so
the reference the MPC would track is reproduced exactly without the arm: the run is built by
``rhmpc.experiment.build_run`` from the same settings as ``rhmpc simulate`` (scenario, ``--rr``,
seed, sensor, ``[reference]`` table: outlier gate, guard), and only its reference is driven, by
the loop's own delivery of the samples (:class:`rhmpc.sim.loop.closed_loop.Refreshes`: the same
refresh on the same tick as in the closed loop). Scored from ``settling`` on, against the
recorded stream (the paper's ground truth, as ``simulate``): the reference's error at 25 ms (the
last horizon point) — RMS, max — and the *episodes*: ticks where it exceeds 1 mm.

    .venv/bin/python benchmarks/reference_bench.py --predictor generalized --seeds 0,3,7 \
        [--scenarios fixed-a2-top,...] [--set reference.KEY=VALUE ...] [--duration 60]
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rhmpc.paper.tables import COLUMNS

SCENARIOS = COLUMNS  # Tuna et al. Tables I–III


def drive(changes: dict) -> Iterator[tuple[int, object, list]]:
    """Build the run of ``changes`` (``RunConfig.replace`` keys) and drive its reference.

    Parameters
    ----------
    changes : dict
        Settings of the run, as ``RunConfig.replace`` takes them (``"scenario"``,
        ``"reference.outlier_gate"``, …).

    Yields
    ------
    tick : int
        Every tick of the run, in order, after the reference's refreshes of that tick.
    run : rhmpc.experiment.assembly.Run
        The run (``run.reference`` is the reference driven).
    arrivals : list of (z, stamp, forecast)
        The samples that refreshed the reference on this tick (in the sensor's frame [m];
        None: no new sample), their time [s], and the one-step forecast the outlier gate
        judged ``z`` by (alike; None while the gate has none).
    """
    from rhmpc.experiment import RunConfig, build_run
    from rhmpc.sim.loop.closed_loop import Refreshes

    config = RunConfig().replace(**changes)
    run = build_run(config)
    reference = run.reference
    refreshes = Refreshes(run.stream, config.loop, run.clock)
    for tick in range(config.loop.ticks):
        arrivals = []
        for z, stamp, _ in refreshes.due(tick):
            forecast = getattr(reference, "_forecast", None)
            arrivals.append((z, stamp, None if forecast is None else forecast.copy()))
            reference.refresh(tick, z, stamp)
        yield tick, run, arrivals


def one(job: tuple) -> tuple[str, int, dict]:
    """Score one ``(scenario, seed, predictor, sets, duration, rr)`` job: RMS and max of the
    25-ms error [mm], the time above 1 mm [ms], and the predictor's counts."""
    scenario, seed, predictor, sets, duration, rr = job
    from rhmpc.experiment.config import parse_value
    from rhmpc.positions import embed3

    changes = {"scenario": scenario, "seed": seed, "predictor": predictor, "rr": rr,
               "loop.duration": duration, "loop.settling": 10.0}
    for item in sets:
        key, _, value = item.partition("=")
        changes[key.strip()] = parse_value(value.strip())
    last, started = [], False
    for tick, run, arrivals in drive(changes):
        started = started or any(z is not None for z, _, _ in arrivals)
        if started and tick >= run.config.loop.settling_ticks:
            last.append(run.reference.horizon(tick)[-1] - run.anchor)
    loop, N = run.config.loop, run.config.mpc.horizon
    first = loop.ticks - len(last)
    truth = embed3(run.truth.window(first + N, loop.ticks + N))
    e = 1e3 * np.linalg.norm(np.asarray(last) - truth, axis=1)
    e = e[np.isfinite(e)]  # the recorded stream has gaps (missing samples)
    counts = dict(getattr(run.reference.predictor, "counts", {}))
    return scenario, seed, {
        "rms": float(math.sqrt(np.mean(e**2))), "max": float(e.max()),
        "episodes_ms": float(np.sum(e > 1.0) * loop.Ts * 1e3),
        "counts": {k: v for k, v in counts.items() if k not in ("updates",)},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--predictor", default="generalized")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--seeds", default="0,3,7")
    ap.add_argument("--set", action="append", default=[],
                    help="SECTION.KEY=VALUE, e.g. reference.outlier_gate=0.0 (repeatable)")
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
