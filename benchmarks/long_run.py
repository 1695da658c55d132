"""A long run: memory and speed of ``rhmpc simulate`` over a long stretch of heart motion.

``rhmpc simulate --predictor generalized --rr mitdb-100 --duration D --json`` in a fresh process:
peak resident memory, wall time, real-time factor, RMS/max error, QP fallbacks.

    python benchmarks/long_run.py [--quick]      # quick: 120 s; else 120 s and 1800 s
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="120 s instead of 1800 s")
    a = ap.parse_args()
    rows, data = [], []
    for duration in ((120.0,) if a.quick else (120.0, 1800.0)):
        cmd = [sys.executable, "-m", "rhmpc.cli", "simulate", "--predictor", "generalized",
               "--rr", "mitdb-100", "--duration", f"{duration:g}", "--json"]
        doc = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
        d = {"command": " ".join(["rhmpc", *cmd[3:]]), "duration_s": duration,
             **{k: doc[k] for k in ("rms_error_mm", "max_error_mm", "fallbacks", "wall_s",
                                    "real_time_factor", "peak_rss_mb")}}
        data.append(d)
        rows.append([R.fmt(duration, 0), R.fmt(d["peak_rss_mb"], 0), R.fmt(d["wall_s"], 1),
                     R.fmt(d["real_time_factor"], 1), R.fmt(d["rms_error_mm"]),
                     R.fmt(d["max_error_mm"]), R.fmt(d["fallbacks"])])
    tab = R.table(["simulated [s]", "peak RSS [MB]", "wall [s]", "× real time", "RMS [mm]",
                   "max [mm]", "fallbacks"], rows)
    R.write("long_run", "Long runs", {"runs": data}, {"": tab}, a.quick,
            notes="MIT-BIH record 100's beat annotations drive the heart phase; the physical "
                  "sonomicrometer; the generalized predictor; default controller.")


if __name__ == "__main__":
    main()
