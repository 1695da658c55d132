"""Results files: every number the README and the documentation publish comes from one of these.

A benchmark script measures, then calls :func:`write`, which puts two files in ``docs/results``:

``NAME.json``
    ``{"name", "title", "command", "version", "date", "quick", "machine": {"cores",
    "gain_tick_us", "load_average", "python", "platform"}, "data": …, "tables": {…}}`` — the
    command that produced it, the package version, the date (UTC), the machine's yardstick (the
    bare gain tick g of ``rhmpc bench`` timed in the same process, and the cores), and the data.
``NAME.md``
    the same data as Markdown tables, with a line stating the command, version, date and
    yardstick; the documentation pages include it (``{include}``) and ``run_all.py`` copies
    the README's table into the README between ``<!-- results:NAME -->`` markers.

Every cell of a table is formatted here from the JSON's values, so each number on a page is a
value of a results file rounded to the digits shown (``tests/test_docs.py`` checks that).
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"


def command_line() -> str:
    """The command that ran this script, as a user would type it from the project's root."""
    script = Path(sys.argv[0]).resolve()
    try:
        script = script.relative_to(ROOT)
    except ValueError:
        pass
    return " ".join(["python", shlex.quote(str(script)), *map(shlex.quote, sys.argv[1:])])


_YARDSTICK: dict | None = None


def yardstick(ticks: int = 2000) -> dict:
    """The machine's yardstick: p50 of ``rhmpc bench``'s gain tick g [µs], and the cores.

    Measured once per process by ``rhmpc bench --ticks 2000 --json`` (a few seconds).
    """
    global _YARDSTICK
    if _YARDSTICK is None:
        import subprocess

        cmd = [sys.executable, "-m", "rhmpc.cli", "bench", "--ticks", str(ticks), "--json"]
        doc = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
        _YARDSTICK = {"gain_tick_us": round(doc["gain_tick_us"]["p50"], 2),
                      "cores": os.cpu_count(), "load_average": round(os.getloadavg()[0], 2)}
    return dict(_YARDSTICK)


#: Every value that :func:`fmt` put in a table of this process, stored in the results file.
SHOWN: list[float] = []


def fmt(value, digits: int = 3, sci: bool = False) -> str:
    """A cell: ``value`` with ``digits`` decimals (integers as they are; None as a dash).

    The value is remembered (:data:`SHOWN`) and written into the results file, so that every
    number of a table is a number of its JSON file.
    """
    if value is None:
        return "—"
    if isinstance(value, bool) or isinstance(value, int | str):
        return str(value)
    SHOWN.append(float(value))
    return f"{value:.{digits}e}" if sci else f"{value:.{digits}f}"


def table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in rows]
    return "\n".join(lines)


def write(name: str, title: str, data, tables: dict[str, str], quick: bool,
          notes: str = "") -> Path:
    """Write ``docs/results/NAME.json`` and ``NAME.md``; returns the JSON's path.

    ``tables``: caption → Markdown table (made with :func:`table` and :func:`fmt` from
    ``data``); a caption ``"slug|Caption"`` also marks the table with ``<!-- table:slug -->``
    comments, so that a page can include that table alone; ``notes``: a paragraph placed
    after the tables (no numbers of its own).
    """
    from rhmpc import __version__

    RESULTS.mkdir(parents=True, exist_ok=True)
    machine = {**yardstick(), "python": platform.python_version(),
               "platform": platform.platform(terse=True)}
    doc = {"name": name, "title": title, "command": command_line(), "version": __version__,
           "date": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d"), "quick": quick,
           "machine": machine, "data": data, "shown": list(SHOWN), "tables": tables}
    SHOWN.clear()
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    md = []
    for key, tab in tables.items():
        slug, _, caption = key.rpartition("|")
        if slug:
            md.append(f"<!-- table:{slug} -->")
        if caption:
            md += [f"**{caption}**", ""]
        md += [tab, ""]
        if slug:
            md += [f"<!-- /table:{slug} -->", ""]
    if notes:
        md += [notes, ""]
    md.append(provenance(doc))
    (RESULTS / f"{name}.md").write_text("\n".join(md) + "\n")
    print(f"wrote {path.relative_to(ROOT)} and {name}.md", file=sys.stderr)
    return path


def provenance(doc: dict) -> str:
    """The line under every generated table: command, version, date, yardstick."""
    m = doc["machine"]
    mode = " (quick settings)" if doc["quick"] else ""
    return (f"*Measured by `{doc['command']}`{mode}: rhmpc {doc['version']}, {doc['date']}; "
            f"machine: {m['cores']} cores, gain tick g = {m['gain_tick_us']} µs, "
            f"load average {m['load_average']}.*")
