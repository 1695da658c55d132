"""Predictor bench: 3-step (~23 ms) forecast RMS on every replica's sonomicrometry stream.

Reproduces the predictor-contract check's stream in-process (scenario and sensor seed
``--seed``, 60 s, every second sample of the 257 Hz sonomicrometer, error against the
measured sample ``z[n+3]``; first 10 s not scored) and also scores against the true motion.
Heart-rate tracking of ekf/wflc (``rhmpc.experiment.monitor.HeartRateScore``, from t = 0)
is reported too.

    .venv/bin/python benchmarks/predictor_streams.py [--clean] [--set wflc:phase_gain=0.0 ...]
"""

from __future__ import annotations

import argparse
import json
import math
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from rhmpc.paper.tables import COLUMNS

REPLICAS = COLUMNS  # Tuna et al. Tables I–III
NAMES = ("hold", "ekf", "dual-ekf", "ar", "fading-ar", "wflc", "one-step", "generalized",
         "last-cycle")


def one(job):
    name, clean, seed, sets, names, rr, init = job
    from rhmpc.experiment.monitor import HeartRateScore
    from rhmpc.predictors import make_predictor
    from rhmpc.sim.heart.scenarios import make_scenario
    from rhmpc.sim.sensors import sensor_from_name

    kw = {"duration": 60.0}
    if clean:
        kw["variability"] = "clean"
    if rr:
        kw["record"] = rr
    scn = make_scenario(name, np.random.default_rng(seed), **kw)
    sensor = sensor_from_name("sonomicrometry", dim=int(scn.source.dim))
    st = sensor.measure(scn.source, scn.duration, np.random.default_rng(seed),
                        t0=getattr(scn, "start", 0.0))
    t, z = st.t[::2], st.z[::2]
    truth = scn.source.position(t)
    dt = float(np.median(np.diff(t)))
    H, warm = 3, int(10 / dt)
    out = {}
    for p_name in names:
        s = dict(sets.get(p_name, {}))
        p = make_predictor(p_name, dt, **s)
        has_hr = hasattr(p, "heart_rate_hz")
        hr = HeartRateScore(scn.source.phase.rate, settling=init) if has_hr else None
        em, et = [], []
        for n in range(len(z) - H):
            p.update(z[n])
            if hr is not None:
                hr.observe(t[n], p.heart_rate_hz)
            if n >= warm:
                f = np.asarray(p.predict(H))[H - 1]
                if np.all(np.isfinite(z[n + H])):
                    em.append(np.linalg.norm(f - z[n + H]))
                et.append(np.linalg.norm(f - truth[n + H]))
        row = {"meas": 1e3 * math.sqrt(np.mean(np.square(em))),
               "true": 1e3 * math.sqrt(np.mean(np.square(et)))}
        if hr is not None:
            row["hr"] = hr.summary()
            row["clamped"] = int(p.counts.get("omega_clamped", 0))
        out[p_name] = row
    return name, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--clean", action="store_true")
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--names", default=",".join(NAMES))
    ap.add_argument("--replicas", default=",".join(REPLICAS))
    ap.add_argument("--set", action="append", default=[], help="name:key=value (JSON value)")
    ap.add_argument("--rr", default=None, help="PhysioNet record driving the heart")
    ap.add_argument("--settling", type=float, default=0.0, help="HR scored from this time [s]")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    sets: dict = {}
    for item in a.set:
        who, kv = item.split(":", 1)
        k, v = kv.split("=", 1)
        sets.setdefault(who, {})[k] = json.loads(v)
    names = a.names.split(",")
    jobs = [(r, a.clean, a.seed, sets, names, a.rr, a.settling) for r in a.replicas.split(",")]
    with ProcessPoolExecutor() as ex:
        res = dict(ex.map(one, jobs))
    if a.json:
        print(json.dumps(res, indent=1, default=str))
        return
    print(f"3-step RMS [mm] vs measured (vs truth); seed {a.seed}, clean={a.clean}, set={sets}")
    print(f"{'replica':<16}" + "".join(f"{n:>18}" for n in names))
    for r, row in res.items():
        print(f"{r:<16}" + "".join(f"{row[n]['meas']:>9.3f} ({row[n]['true']:.3f})" for n in names))
    for n in names:
        if "hr" not in next(iter(res.values()))[n]:
            continue
        print(f"\n{n}: HR vs truth (lock: within 5 bpm from then on; t ≥ {a.settling:g} s)")
        cols = ("ready s", "lock s", "rms bpm", "max bpm", "within")
        print(f"{'replica':<16}" + "".join(f"{c:>9}" for c in cols) + f"{'clamp':>6}")
        for r, row in res.items():
            h = row[n]["hr"]
            vals = (h.get("ready_time_s"), h.get("lock_time_s"), h.get("rms_error_bpm"),
                    h.get("max_error_bpm"), h.get("within_tolerance"))
            print(f"{r:<16}" + "".join(f"{v if v is not None else math.nan:>9.2f}" for v in vals)
                  + f"{row[n]['clamped']:>6}")


if __name__ == "__main__":
    main()
