"""The comparison table: predictors × columns (scenarios or recordings), with ratios to a
reference row, as text within :data:`MAX_WIDTH` characters or as CSV.

A cell holds the runs of one predictor on one column, one per seed: their mean, and with two
runs or more the half-width of the 95 % confidence interval of the mean (Student t with n − 1
degrees of freedom). The ratios are to ``exact`` on scenarios (Tuna et al.'s yardstick) and to
``hold`` on recordings, where ``exact`` reads the recorded future and is no yardstick.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["MAX_WIDTH", "METRICS", "Cell", "cells", "cells_document", "comparison_csv",
           "comparison_table", "grid", "interval95", "json_ready", "reference_row"]

#: Widest line of a table; a wider table is transposed, then split into blocks.
MAX_WIDTH = 120
#: The metrics of a cell (keys of the run documents).
METRICS = ("rms_error_mm", "max_error_mm", "rms_effort_mNm")
_TITLES = {"rms_error_mm": "RMS position error [mm]", "max_error_mm": "maximum error [mm]",
           "rms_effort_mNm": "RMS control effort [mN·m]"}
_GAP = 2


@dataclass(frozen=True)
class Cell:
    """The runs of one predictor on one column.

    Attributes
    ----------
    n : int
        Runs that finished.
    failed : int
        Runs that failed.
    mean : dict[str, float]
        Mean of each metric (:data:`METRICS`) over the finished runs.
    half : dict[str, float]
        Half-width of each mean's 95 % interval (NaN with fewer than two runs).
    """

    n: int = 0
    failed: int = 0
    mean: dict[str, float] = field(default_factory=dict)
    half: dict[str, float] = field(default_factory=dict)

    @property
    def status(self) -> str:
        """``"ok"``, ``"failed"`` (every run failed) or ``"not run"``."""
        return "ok" if self.n else "failed" if self.failed else "not run"

    def text(self, metric: str, digits: int, runs: int) -> str:
        """``0.403``, ``0.403 ± 0.012``; ``(n=9)`` appended when fewer than ``runs``
        finished; ``failed`` or ``-`` for a cell without a result."""
        if not self.n:
            return "failed" if self.failed else "-"
        out = f"{self.mean[metric]:.{digits}f}"
        if math.isfinite(self.half.get(metric, math.nan)):
            out += f" ± {self.half[metric]:.{digits}f}"
        return out + (f" (n={self.n})" if self.n < runs else "")


def interval95(values: Sequence[float]) -> tuple[float, float]:
    """Mean and half-width of its 95 % confidence interval (Student t, n − 1 degrees of freedom).

    Parameters
    ----------
    values : sequence of float
        One value per run.

    Returns
    -------
    tuple[float, float]
        ``(mean, half)``; ``half`` is NaN for fewer than two values, the mean NaN for none.
    """
    from scipy.stats import t

    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return math.nan, math.nan
    if a.size == 1:
        return float(a[0]), math.nan
    half = t.ppf(0.975, a.size - 1) * a.std(ddof=1) / math.sqrt(a.size)
    return float(a.mean()), float(half)


def cells(docs: Sequence[dict], predictors: Sequence[str],
          columns: Sequence[str]) -> dict[tuple[str, str], Cell]:
    """Every (predictor, column) cell of the run documents.

    Parameters
    ----------
    docs : sequence of dict
        Run documents: ``predictor``, ``scenario`` (the column) and the metrics; a document
        with ``error`` is a failed run.
    predictors, columns : sequence of str
        The cells to make.

    Returns
    -------
    dict[tuple[str, str], Cell]
        Keyed by (predictor, column).
    """
    out = {}
    for pred in predictors:
        for col in columns:
            rows = [d for d in docs if d.get("predictor") == pred and d.get("scenario") == col]
            ok = [d for d in rows if "error" not in d and "rms_error_mm" in d]
            stats = {m: interval95([d[m] for d in ok]) for m in METRICS}
            out[pred, col] = Cell(len(ok), len(rows) - len(ok),
                                  {m: v[0] for m, v in stats.items()},
                                  {m: v[1] for m, v in stats.items()})
    return out


def cells_document(docs: Sequence[dict], predictors: Sequence[str],
                   columns: Sequence[str]) -> list[dict]:
    """The cells as data: per predictor and column, ``runs``, ``failed`` and, per metric of
    :data:`METRICS`, ``mean`` and ``ci95`` ([low, high] of the mean's 95 % interval; None
    below two runs)."""
    out = []
    for (pred, col), c in cells(docs, predictors, columns).items():
        out.append({"predictor": pred, "column": col, "runs": c.n, "failed": c.failed,
                    **{m: {"mean": c.mean[m], "ci95": [c.mean[m] - c.half[m],
                                                       c.mean[m] + c.half[m]]}
                       for m in METRICS}})
    return out


def json_ready(obj):
    """``obj`` with every non-finite float as None (strict JSON) and numpy scalars as Python's."""
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def reference_row(predictors: Sequence[str], recordings: bool = False) -> str | None:
    """The row the ratios are to: ``exact`` (``hold`` on recordings), else the other one."""
    for pred in ("hold", "exact") if recordings else ("exact", "hold"):
        if pred in predictors:
            return pred
    return None


def runs_line(table: dict[tuple[str, str], Cell], seeds: Sequence[int] = ()) -> str:
    """The line that says what stands behind a cell: one run, or the mean and the interval over
    N runs (and the seeds)."""
    runs = max((c.n + c.failed for c in table.values()), default=0)
    which = f" (seed {seeds[0]})" if len(seeds) == 1 else (
        f" (seeds {min(seeds)}–{max(seeds)})" if seeds else "")
    if runs <= 1:
        return f"Each cell: 1 run{which}."
    short = any(0 < c.n < runs for c in table.values())
    return (f"Each cell: mean ± half-width of the 95 % interval (Student t) over {runs} runs"
            f"{which}" + ("; (n=k): only k finished." if short else "."))


def comparison_table(docs: Sequence[dict], predictors: Sequence[str],
                     scenarios: Sequence[str], recordings: bool = False,
                     seeds: Sequence[int] = ()) -> str:
    """Tuna Tables I–III replica: error [mm] and effort [mN·m] per predictor and column, and
    the ratios to the reference row.

    Parameters
    ----------
    docs : sequence of dict
        Run documents (``predictor``, ``scenario`` = the column, the metrics or ``error``).
    predictors, scenarios : sequence of str
        Rows and columns, in order.
    recordings : bool
        The columns are recordings: the ratios are to ``hold`` (:func:`reference_row`).
    seeds : sequence of int
        The seeds run, for the line that says what stands behind a cell.

    Returns
    -------
    str
        One table per metric (RMS and maximum error in one table with one run per cell),
        each at most :data:`MAX_WIDTH` wide; a cell without a result reads ``failed``.
    """
    table = cells(docs, predictors, scenarios)
    runs = max((c.n + c.failed for c in table.values()), default=0)
    out = [runs_line(table, seeds)]
    where = _where(docs)
    if runs <= 1:
        out += ["", *grid(f"RMS position error [mm] (maximum error [mm]){where}", predictors,
                          scenarios, lambda p, s: _rms_max(table[p, s]))]
        metrics: tuple[str, ...] = ("rms_effort_mNm",)
    else:
        metrics = METRICS
    for metric in metrics:
        title = _TITLES[metric] + (where if metric != "rms_effort_mNm" else "")
        out += ["", *grid(title, predictors, scenarios,
                          lambda p, s, m=metric: table[p, s].text(m, _digits(m), runs))]
    reference = reference_row(predictors, recordings)
    if reference is not None and len(predictors) > 1:
        rows = [p for p in predictors if p != reference]
        why = (" (exact reads the recorded future: no yardstick on a recording)"
               if recordings and reference == "hold" else "")
        out += ["", *grid(f"ratio to {reference}: RMS error / RMS effort{why}", rows, scenarios,
                          lambda p, s: _ratio(table[p, s], table[reference, s]))]
    return "\n".join(out)


def _where(docs: Sequence[dict]) -> str:
    """Where the errors were taken: at a recording's measured instants, or at every tick."""
    scores = {d.get("score") for d in docs if "error" not in d}
    if scores == {"measured"}:
        return ", at the measured instants"
    return ", at every tick" if scores == {"continuous"} else ""


def _digits(metric: str) -> int:
    return 2 if metric == "rms_effort_mNm" else 3


def _rms_max(cell: Cell) -> str:
    if not cell.n:
        return cell.text("rms_error_mm", 3, 1)
    return f"{cell.mean['rms_error_mm']:.3f} ({cell.mean['max_error_mm']:.3f})"


def _ratio(cell: Cell, ref: Cell) -> str:
    if not (cell.n and ref.n):
        return "failed" if cell.status == "failed" or ref.status == "failed" else "-"
    return (f"{cell.mean['rms_error_mm'] / ref.mean['rms_error_mm']:.2f} / "
            f"{cell.mean['rms_effort_mNm'] / ref.mean['rms_effort_mNm']:.2f}")


def comparison_csv(docs: Sequence[dict], predictors: Sequence[str], columns: Sequence[str],
                   recordings: bool = False) -> str:
    """The cells as CSV: one line per column and predictor, with the runs behind it, each
    metric's mean and 95 % half-width (empty below two runs), and the ratios to the reference.

    Parameters
    ----------
    docs : sequence of dict
        Run documents, as for :func:`comparison_table`.
    predictors, columns : sequence of str
        Rows and columns of the table.
    recordings : bool
        The columns are recordings: the ratios are to ``hold``.

    Returns
    -------
    str
        The CSV text with a header line (``column, predictor, runs, failed, rms_error_mm,
        rms_error_mm_ci95, ..., reference, error_ratio, effort_ratio``).
    """
    table = cells(docs, predictors, columns)
    reference = reference_row(predictors, recordings)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["column", "predictor", "runs", "failed",
                     *(f"{m}{suffix}" for m in METRICS for suffix in ("", "_ci95")),
                     "reference", "error_ratio", "effort_ratio"])
    for col in columns:
        for pred in predictors:
            c = table[pred, col]
            ref = table.get((reference, col)) if reference else None
            stats = [_num(v) for m in METRICS for v in (c.mean.get(m), c.half.get(m))]
            ratios = ["", ""]
            if ref is not None and c.n and ref.n:
                ratios = [_num(c.mean[m] / ref.mean[m]) for m in ("rms_error_mm",
                                                                   "rms_effort_mNm")]
            writer.writerow([col, pred, c.n, c.failed, *stats, reference or "", *ratios])
    return buf.getvalue()


def _num(x: float | None) -> str:
    return "" if x is None or not math.isfinite(x) else f"{x:.6g}"


def grid(title: str, rows: Sequence[str], cols: Sequence[str],
         text: Callable[[str, str], str], width: int = MAX_WIDTH) -> list[str]:
    """A titled table of ``text(row, col)`` cells, at most ``width`` characters wide.

    The table is laid out with ``rows`` down and ``cols`` across; if that is too wide, it is
    transposed (``cols`` down); if that is still too wide, the narrower layout is split into
    blocks of columns.

    Returns
    -------
    list[str]
        The title, then the header and rows of each block (blocks apart by a blank line).
    """
    layouts = [(rows, cols, text), (cols, rows, lambda c, r: text(r, c))]
    rendered = [_render(*layout) for layout in layouts]
    for lines in rendered:
        if max(map(len, lines)) <= width:
            return [title, *lines]
    down, across, cell = min(layouts, key=lambda lay: max(map(len, _render(*lay))))
    out = [title]
    for block in _blocks(down, across, cell, width):
        out += [*([""] if len(out) > 1 else []), *_render(down, block, cell)]
    return out


def _widths(down: Sequence[str], across: Sequence[str],
            cell: Callable[[str, str], str]) -> tuple[int, list[int]]:
    label = max((len(r) for r in down), default=0)
    return label, [max(len(c), *(len(cell(r, c)) for r in down)) for c in across]


def _render(down: Sequence[str], across: Sequence[str],
            cell: Callable[[str, str], str]) -> list[str]:
    label, widths = _widths(down, across, cell)
    pad = " " * _GAP
    lines = [" " * label + "".join(pad + c.rjust(w) for c, w in zip(across, widths,
                                                                       strict=True))]
    for r in down:
        lines.append(r.ljust(label) + "".join(pad + cell(r, c).rjust(w)
                                              for c, w in zip(across, widths, strict=True)))
    return lines


def _blocks(down: Sequence[str], across: Sequence[str], cell: Callable[[str, str], str],
            width: int) -> list[list[str]]:
    """``across`` cut into consecutive blocks whose table fits ``width`` (one column at least)."""
    label, widths = _widths(down, across, cell)
    blocks: list[list[str]] = [[]]
    used = label
    for c, w in zip(across, widths, strict=True):
        if blocks[-1] and used + _GAP + w > width:
            blocks.append([])
            used = label
        blocks[-1].append(c)
        used += _GAP + w
    return blocks
