"""Regenerate every results file of the documentation and the README's table and figure.

    python benchmarks/run_all.py [--quick] [--only NAME,...]

Runs each benchmark below in turn (one process at a time), then copies
``docs/results/headline.md`` into README.md between its ``<!-- results:headline -->`` markers.
``--quick`` shortens every run (minutes in all instead of tens of minutes); the files say so.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: The benchmarks that write docs/results/NAME.json, in the order they run.
SCRIPTS = ("headline", "tuna_tables", "hardware_sensitivity", "causal_bound", "yuen_noise",
           "mpc_timing", "exported_tick", "predictor_table", "invivo_table", "design_choices",
           "long_run", "faults", "learned_table")
MARK = re.compile(r"(<!-- results:(\w+) -->\n).*?(<!-- /results:\2 -->)", re.S)


def sync_readme(readme: Path = ROOT / "README.md") -> bool:
    """Replace each marked block of the README with its results file's Markdown."""
    text = readme.read_text()

    def fill(m: re.Match) -> str:
        md = (ROOT / "docs" / "results" / f"{m.group(2)}.md").read_text()
        return m.group(1) + md + m.group(3)

    new = MARK.sub(fill, text)
    if new != text:
        readme.write_text(new)
    return new != text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", default=",".join(SCRIPTS),
                    help=f"comma-separated names among {', '.join(SCRIPTS)}")
    a = ap.parse_args()
    names = [n.strip() for n in a.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in SCRIPTS]
    if unknown:
        ap.error(f"no benchmark named {', '.join(unknown)} (choose among {', '.join(SCRIPTS)})")
    for name in names:
        t0 = time.perf_counter()
        cmd = [sys.executable, str(HERE / f"{name}.py"), *(["--quick"] if a.quick else [])]
        print(f"run_all: {name} …", file=sys.stderr, flush=True)
        subprocess.run(cmd, check=True, cwd=ROOT)
        print(f"run_all: {name} done in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if sync_readme():
        print("run_all: README.md updated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
