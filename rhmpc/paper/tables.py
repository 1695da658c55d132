"""The published tables of Tuna et al. (T-RO 2013) beside ours, and which findings reproduce.

Our cell is the mean of the runs over the seeds with the 95 % interval of the mean (Student t);
the published cell is the maximum over ten runs whose deviation "had been very small"
(§VIII-B), so the two are set side by side as they are, with their ratio ours ÷ paper. The
findings are judged by :mod:`rhmpc.paper.findings`.

A run belongs beside the simulation table (Table I) unless its plant is the hardware-like one
(some of ``[plant]``'s hardware effects on, ``--preset hardware``, Tables II–III):
:func:`paper_table` never sets one against the other's table, and a cell whose runs all failed
reads ``failed``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from rhmpc.compare.table import grid, interval95
from rhmpc.paper.findings import CROSS, findings
from rhmpc.paper.tuna2013 import COLUMNS, SETTING, TUNA2013
from rhmpc.sim.plant import PlantSettings

__all__ = ["COLUMNS", "SETTING", "TUNA2013", "cell", "paper_document", "paper_table",
           "setting_of", "table_predictors"]

_TITLES = {"I": "Table I (simulation)", "II": "Table II (hardware experiments)",
           "III": "Table III (hardware experiments, EKF)"}
_METRICS = {"rms_error_mm": "RMS position error [mm]", "max_error_mm": "maximum error [mm]",
            "rms_effort_mNm": "RMS control effort [mN·m]"}


def table_predictors(setting: str) -> tuple[str, ...]:
    """The rows of the published tables of ``setting``, in the tables' order."""
    rows = [p for (table, _), cells in TUNA2013.items() if SETTING[table] == setting
            for p in cells]
    return tuple(dict.fromkeys(rows))


def setting_of(docs: Sequence[dict]) -> str:
    """``"hardware"`` when every run's plant is the hardware-like one, else ``"simulation"``.

    Documents without settings (a run that failed before it had any) do not count.
    """
    models = {plant_label(d["settings"]) for d in docs if isinstance(d.get("settings"), dict)}
    return "hardware" if models == {"hardware"} else "simulation"


def plant_label(settings: dict) -> str:
    """The plant of a run's settings: ``"linear"``, ``"ideal"`` or ``"hardware"``
    (:attr:`PlantSettings.label`; a document of an earlier version names it ``plant.model``; a
    table it cannot read: ``"?"``)."""
    plant = settings.get("plant", {})
    if isinstance(plant, dict) and "model" in plant:
        return str(plant["model"])
    try:
        return PlantSettings(**plant).label
    except (TypeError, ValueError):
        return "?"


def cell(docs: Sequence[dict], predictor: str, scenario: str, metric: str) -> dict:
    """Our cell: ``runs`` finished, ``failed``, ``mean``, ``ci95`` ([low, high] of the mean;
    NaN below two runs) and ``max`` (the paper's statistic) of ``metric``."""
    rows = [d for d in docs if d.get("predictor") == predictor and d.get("scenario") == scenario]
    values = [float(d[metric]) for d in rows if "error" not in d and metric in d]
    mean, half = interval95(values)
    return {"runs": len(values), "failed": len(rows) - len(values), "mean": mean,
            "ci95": [mean - half, mean + half], "max": max(values, default=math.nan)}


def _runs_per_cell(docs: Sequence[dict]) -> int:
    counts: dict[tuple, int] = {}
    for d in docs:
        key = (d.get("predictor"), d.get("scenario"))
        counts[key] = counts.get(key, 0) + 1
    return max(counts.values(), default=0)


def _seeds(docs: Sequence[dict]) -> str:
    seeds = sorted({d["seed"] for d in docs if isinstance(d.get("seed"), int)})
    if not seeds:
        return ""
    return f" (seed {seeds[0]})" if len(seeds) == 1 else f" (seeds {seeds[0]}–{seeds[-1]})"


def _header(docs: Sequence[dict], setting: str) -> list[str]:
    """What our runs are, against which of Tuna's settings, and what a cell holds."""
    runs = [d for d in docs if isinstance(d.get("settings"), dict)]
    plant = {plant_label(d["settings"]) for d in runs}
    hw = {d["settings"].get("plant", {}).get("error_from", "true") for d in runs}
    n = _runs_per_cell(docs)
    tables = "Tables II–III" if setting == "hardware" else "Table I"
    ours = (f"the mean ± the half-width of its 95 % interval over {n} runs" if n > 1
            else "1 run")
    lines = [f"Our runs: plant {', '.join(sorted(plant)) or '-'}; set beside {tables} "
             f"({setting}) only.",
             f"Each cell: paper / ours / ours ÷ paper; ours = {ours}{_seeds(docs)},",
             "  Tuna's = the maximum over ten runs (their deviation \"very small\", §VIII-B)."]
    if any(c["failed"] for c in _our_cells(docs)):
        lines.append("(n=k): only k of our runs finished; failed: none did.")
    if setting == "simulation" and plant != {"linear"}:
        lines.append("Note: Tuna's Table I plant is a linearised reduced-order model; ours "
                     "here is not (plant.kind = \"linear\" is, --preset tuna2013).")
    if setting == "hardware" and hw != {"encoders"}:
        lines.append("Note: Tuna's hardware error is the encoders' forward kinematics; ours "
                     "here is the arm's true tip (plant.error_from).")
    return lines


def _our_cells(docs: Sequence[dict]) -> list[dict]:
    keys = dict.fromkeys((d.get("predictor"), d.get("scenario")) for d in docs)
    return [cell(docs, p, s, "rms_error_mm") for p, s in keys]


def _text(paper: float, mine: dict, runs: int) -> str:
    """``paper / mean ± half / mean÷paper``, ``paper / failed`` or ``paper / -`` (not run)."""
    if not mine["runs"]:
        return f"{paper:.3f} / {'failed' if mine['failed'] else '-'}"
    mean, (low, high) = mine["mean"], mine["ci95"]
    ours = f"{mean:.3f}" + (f" ± {(high - low) / 2:.3f}" if math.isfinite(high) else "")
    short = f" (n={mine['runs']})" if mine["runs"] < runs else ""
    return f"{paper:.3f} / {ours} / {mean / paper:.2f}{short}"


def _tables(setting: str, predictors: Sequence[str]):
    """(table, metric, published rows) of ``setting`` for the predictors run."""
    for (table, metric), published in TUNA2013.items():
        rows = [p for p in published if p in predictors]
        if SETTING[table] == setting and rows:
            yield table, metric, {p: published[p] for p in rows}


def paper_table(docs: Sequence[dict], predictors: Sequence[str],
                scenarios: Sequence[str], setting: str | None = None) -> str:
    """Tuna's tables of our runs' setting beside ours, then one line per published finding.

    Parameters
    ----------
    docs : sequence of dict
        Run documents; a document with ``error`` is a failed run.
    predictors, scenarios : sequence of str
        What was run.
    setting : str, optional
        ``"simulation"`` or ``"hardware"``: the runs' setting, as the caller configured them
        (default: :func:`setting_of` the documents).

    Returns
    -------
    str
        The header, the tables (cells not run show ``-``, cells whose runs all failed
        ``failed``), the findings with their verdicts and causes, and what needs both settings.
    """
    setting = setting or setting_of(docs)
    cols = [s for s in COLUMNS if s in scenarios]
    out = _header(docs, setting)
    runs = _runs_per_cell(docs)
    for table, metric, published in _tables(setting, predictors):
        out += ["", *grid(f"{_TITLES[table]}: {_METRICS[metric]} — paper / ours / ours÷paper",
                          list(published), cols,
                          lambda p, s, m=metric, pub=published: _text(
                              pub[p][s], cell(docs, p, s, m), runs))]
    out += ["", "Published findings (ours; a column decides when the 95 % interval of its "
            "paired difference excludes 0):"]
    out += [f"  {f.line()}" for f in findings(docs, setting, cols)]
    out += [f"  Also published: {CROSS.title} ({CROSS.source}): needs both presets' runs; "
            "the documentation's page on Tuna et al. sets them side by side."]
    return "\n".join(out)


def paper_document(docs: Sequence[dict], predictors: Sequence[str],
                   scenarios: Sequence[str], setting: str | None = None) -> dict:
    """:func:`paper_table` as data: ``setting``, ``cells`` (table, metric, predictor,
    scenario, paper, and ours: runs, mean, ci95, max, ratio) and ``findings`` (each with its
    ``verdict``, per-column outcomes and ``cause``)."""
    setting = setting or setting_of(docs)
    cols = [s for s in COLUMNS if s in scenarios]
    cells = []
    for table, metric, published in _tables(setting, predictors):
        for p, row in published.items():
            for s in cols:
                mine = cell(docs, p, s, metric)
                cells.append({"table": table, "metric": metric, "predictor": p, "scenario": s,
                              "paper": row[s], **mine, "ratio": mine["mean"] / row[s]})
    return {"setting": setting, "tables": [t for t, s in SETTING.items() if s == setting],
            "cells": cells, "findings": [f.to_dict() for f in findings(docs, setting, cols)],
            "needs_both_settings": [CROSS.title]}
