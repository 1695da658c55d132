"""Tuna et al.'s published findings, each judged on our runs with 95 % intervals over seeds.

A finding is a relation between rows of a published table that the paper states column by
column, e.g. "the generalized predictor outperforms the one-step predictor in all simulations
and all experiments" (Tuna et al. 2013, §VIII-B). Each relation is a *margin* :math:`m`, negative
where the relation holds, computed per column and seed from runs of the same seed (the same
heart motion and sensor noise: a paired comparison). Over the :math:`n` seeds of a column,

.. math::

    \\bar m = \\frac{1}{n} \\sum_s m_s, \\qquad
    h = t_{0.975,\\,n-1}\\, \\frac{s_m}{\\sqrt n},

and the column *holds* when :math:`\\bar m + h < 0`, *fails* when :math:`\\bar m - h > 0`, and is
*undecided* when the interval :math:`[\\bar m - h, \\bar m + h]` straddles 0 (or with a single
seed, which gives no interval). The paper's count :math:`k_p` is the relation evaluated on the
published cells. The finding is

- ``"reproduced"`` when at least :math:`k_p` columns hold,
- ``"not reproduced"`` when fewer than :math:`k_p` columns can hold (holding + undecided
  :math:`< k_p`),
- ``"undecided"`` otherwise.

Each finding carries its measured cause: the ratio of the relation's two sides, the rows'
25-ms forecast errors (the run documents' ``prediction_rms_mm.lead_N``), and the runs of its
rows in which the controller fell back from its QP solution (``fallbacks``), which can move a
cell by themselves.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from rhmpc.compare.table import interval95
from rhmpc.paper.tuna2013 import COLUMNS, SETTING, TUNA2013

__all__ = ["CROSS", "RELATIONS", "VERDICTS", "Finding", "Relation", "cross_finding",
           "findings", "judge"]

#: The three verdicts of a finding.
VERDICTS = ("reproduced", "not reproduced", "undecided")


@dataclass(frozen=True)
class Relation:
    """One published finding as a margin per column, negative where it holds.

    Attributes
    ----------
    title : str
        The finding in words.
    source : str
        Where the paper states it.
    metric : str
        The run documents' metric it compares.
    tables : tuple[str, ...]
        The published tables (``"I"``, ``"II"``, ``"III"``) that show it.
    rows : tuple[str, ...]
        The predictors it needs.
    margin : callable
        ``margin(values)`` with ``values`` the rows' metric in one column → the margin
        (same unit as the metric, or a ratio).
    sides : tuple[str, str]
        The rows whose ratio is the measured size (numerator, denominator).
    """

    title: str
    source: str
    metric: str
    tables: tuple[str, ...]
    rows: tuple[str, ...]
    margin: Callable[[dict[str, float]], float]
    sides: tuple[str, str]


_RLS = ("one-step", "generalized")


def _rls_best(v: dict[str, float]) -> float:
    return min(v["one-step"], v["generalized"])


#: The findings stated in Tuna et al. 2013, §VIII-B and §VIII-C.
RELATIONS: tuple[Relation, ...] = (
    Relation("generalized ≤ one-step (RMS error)", "§VIII-B: \"the generalized predictor "
             "outperforms the one-step predictor in all simulations and all experiments\"",
             "rms_error_mm", ("I", "II"), _RLS,
             lambda v: v["generalized"] - v["one-step"], ("generalized", "one-step")),
    Relation("generalized ≤ exact in simulation (RMS error)", "§VIII-B: \"in our simulations "
             "the generalized estimator outperformed the exact heart signal\"",
             "rms_error_mm", ("I",), ("exact", "generalized"),
             lambda v: v["generalized"] - v["exact"], ("generalized", "exact")),
    Relation("exact lowest RMS error on hardware", "§VIII-B: \"the controller with exact heart "
             "signal reference performs better\"", "rms_error_mm", ("II",), ("exact", *_RLS),
             lambda v: v["exact"] - _rls_best(v), ("generalized", "exact")),
    Relation("exact lowest maximum error on hardware", "§VIII-B: \"Maximum error ... for the "
             "exact heart signal are also smaller\"", "max_error_mm", ("II",),
             ("exact", *_RLS), lambda v: v["exact"] - _rls_best(v), ("generalized", "exact")),
    Relation("EKF behind both RLS predictors (RMS error)", "§VIII-C: \"the proposed adaptive "
             "algorithms outperformed the EKF-based algorithm\"", "rms_error_mm", ("III",),
             ("ekf", *_RLS), lambda v: max(v["one-step"], v["generalized"]) - v["ekf"],
             ("ekf", "generalized")),
    Relation("exact lowest RMS effort", "Tables I(b) and II(b)", "rms_effort_mNm",
             ("I", "II"), ("exact", *_RLS), lambda v: v["exact"] - _rls_best(v),
             ("generalized", "exact")),
    Relation("one-step highest RMS effort", "Tables I(b) and II(b)", "rms_effort_mNm",
             ("I", "II"), ("exact", *_RLS),
             lambda v: max(v["exact"], v["generalized"]) - v["one-step"],
             ("one-step", "generalized")),
)

#: Hardware effort above simulation effort (Tables II(b) against I(b), every row and column):
#: measured only with both settings' runs (:func:`cross_finding`).
CROSS = Relation("hardware RMS effort above simulation RMS effort", "Tables I(b) and II(b)",
                 "rms_effort_mNm", ("I", "II"), ("exact", *_RLS),
                 lambda v: v["simulation"] - v["hardware"], ("hardware", "simulation"))


@dataclass(frozen=True)
class Finding:
    """A published finding judged on our runs.

    Attributes
    ----------
    relation : Relation
        What is judged.
    published : str
        The paper's tables and count (``"Table II: 6/6 columns"``).
    required : int
        Columns that must hold: the paper's count.
    columns : list[dict]
        Per column: ``scenario``, ``seeds`` (paired runs), ``margin`` (mean), ``ci95`` ([low,
        high]; NaN with one seed) and ``outcome`` (``holds``, ``fails``, ``undecided``).
    cause : str
        The measured cause: the ratio of the two sides and the forecast errors.
    """

    relation: Relation
    published: str
    required: int
    columns: list[dict]
    cause: str

    def count(self, outcome: str) -> int:
        return sum(c["outcome"] == outcome for c in self.columns)

    @property
    def verdict(self) -> str:
        """``reproduced``, ``not reproduced`` or ``undecided`` (see the module's rule)."""
        holds, undecided = self.count("holds"), self.count("undecided")
        if holds >= self.required:
            return "reproduced"
        if holds + undecided < self.required:
            return "not reproduced"
        return "undecided"

    def line(self) -> str:
        """``[reproduced] TITLE (published …): holds in k/n columns …; cause: …``."""
        n = len(self.columns)
        seeds = max((c["seeds"] for c in self.columns), default=0)
        counts = (f"holds in {self.count('holds')}/{n} columns, fails in "
                  f"{self.count('fails')}, undecided in {self.count('undecided')}")
        basis = (f"95 % intervals of the paired difference over {seeds} seeds" if seeds > 1
                 else "one seed: no interval, --seeds 2 or more decides")
        return (f"[{self.verdict}] {self.relation.title} (published {self.published}): "
                f"{counts} ({basis}); cause: {self.cause}")

    def to_dict(self) -> dict:
        return {"finding": self.relation.title, "source": self.relation.source,
                "published": self.published, "required_columns": self.required,
                "verdict": self.verdict, "holds": self.count("holds"),
                "fails": self.count("fails"), "undecided": self.count("undecided"),
                "columns": self.columns, "cause": self.cause}


def judge(margins: Sequence[float]) -> dict:
    """A column's outcome from its paired margins (one per seed).

    Returns
    -------
    dict
        ``seeds``, ``margin`` (the mean), ``ci95`` ([low, high]) and ``outcome``.
    """
    mean, half = interval95(margins)
    if not math.isfinite(half):
        outcome = "undecided"
    elif mean + half < 0:
        outcome = "holds"
    elif mean - half > 0:
        outcome = "fails"
    else:
        outcome = "undecided"
    return {"seeds": len(margins), "margin": mean, "ci95": [mean - half, mean + half],
            "outcome": outcome}


def _by_seed(docs: Sequence[dict], scenario: str, rows: Sequence[str],
             metric: str) -> dict[int, dict[str, float]]:
    """seed → row → metric, for the seeds where every row finished on ``scenario``."""
    out: dict[int, dict[str, float]] = {}
    for d in docs:
        if d.get("scenario") == scenario and d.get("predictor") in rows and "error" not in d \
                and metric in d:
            out.setdefault(d["seed"], {})[d["predictor"]] = float(d[metric])
    return {s: v for s, v in out.items() if set(rows) <= set(v)}


def _published_count(relation: Relation, table: str, cols: Sequence[str]) -> int:
    """Columns where the relation holds on the published cells of ``table``."""
    cells = TUNA2013[(table, relation.metric)]
    if table == "III":  # Table III repeats Table II(a)'s RLS rows beside the EKF
        cells = {**TUNA2013[("II", relation.metric)], **cells}
    return sum(relation.margin({r: cells[r][c] for r in relation.rows}) < 0 for c in cols)


def _forecast(docs: Sequence[dict], rows: Sequence[str], cols: Sequence[str]) -> str:
    """``25-ms forecast error generalized 0.41 mm, one-step 0.39 mm`` (RMS over runs)."""
    parts = []
    for row in rows:
        values = [d["prediction_rms_mm"]["lead_N"] for d in docs
                  if d.get("predictor") == row and d.get("scenario") in cols
                  and isinstance(d.get("prediction_rms_mm"), dict) and row != "exact"]
        if values:
            parts.append(f"{row} {np.sqrt(np.mean(np.square(values))):.3f} mm")
    return "25-ms forecast error " + ", ".join(parts) if parts else ""


def _fallbacks(docs: Sequence[dict], rows: Sequence[str], cols: Sequence[str]) -> str:
    """``runs that fell back: exact on varying-a3-side seed 8 (54464 ticks: brake)``."""
    runs = [d for d in docs if d.get("predictor") in rows and d.get("scenario") in cols
            and d.get("fallbacks")]
    if not runs:
        return ""
    parts = []
    for d in runs:
        kinds = ", ".join(k for k, v in (d.get("controller", {}).get("fallbacks") or {}).items()
                          if v)
        parts.append(f"{d['predictor']} on {d['scenario']} seed {d['seed']} "
                     f"({d['fallbacks']} ticks{': ' + kinds if kinds else ''})")
    return "runs whose controller fell back from the QP: " + "; ".join(parts)


def _ratio(relation: Relation, paired: list[dict[int, dict[str, float]]]) -> str:
    """``generalized ÷ one-step RMS error 1.02–1.05`` over the columns' means."""
    top, bottom = relation.sides
    ratios = [np.mean([v[top] for v in p.values()]) / np.mean([v[bottom] for v in p.values()])
              for p in paired if p]
    if not ratios:
        return ""
    what = relation.metric.removesuffix("_mm").removesuffix("_mNm").replace("_", " ")
    return f"{top} ÷ {bottom} {what} {min(ratios):.2f}–{max(ratios):.2f}"


def findings(docs: Sequence[dict], setting: str,
             cols: Sequence[str] = COLUMNS) -> list[Finding]:
    """Every published finding of ``setting`` (``"simulation"`` or ``"hardware"``) whose rows
    were run, judged on the run documents ``docs`` (failed runs left out)."""
    tables = [t for t, s in SETTING.items() if s == setting]
    cols = [c for c in COLUMNS if c in cols]
    run = {d.get("predictor") for d in docs}
    out = []
    for relation in RELATIONS:
        mine = [t for t in relation.tables if t in tables]
        if not mine or not set(relation.rows) <= run:
            continue
        paired = [_by_seed(docs, c, relation.rows, relation.metric) for c in cols]
        columns = [{"scenario": c, **judge([relation.margin(v) for v in p.values()])}
                   for c, p in zip(cols, paired, strict=True)]
        counts = [_published_count(relation, t, cols) for t in mine]
        published = "; ".join(f"Table {t}: {k}/{len(cols)} columns"
                              for t, k in zip(mine, counts, strict=True))
        cause = "; ".join(x for x in (_ratio(relation, paired),
                                      _forecast(docs, relation.rows, cols),
                                      _fallbacks(docs, relation.rows, cols)) if x)
        out.append(Finding(relation, published, min(counts), columns, cause))
    return out


def cross_finding(simulation: Sequence[dict], hardware: Sequence[dict],
                  cols: Sequence[str] = COLUMNS) -> Finding:
    """Hardware effort above simulation effort (:data:`CROSS`), per row and column, paired by
    seed across the two settings' runs (the same seed: the same heart motion and noise)."""
    cols = [c for c in COLUMNS if c in cols]
    columns, paired = [], []
    for row in CROSS.rows:
        for c in cols:
            sim, hw = (_by_seed([d for d in docs if d.get("predictor") == row], c, (row,),
                                CROSS.metric) for docs in (simulation, hardware))
            pairs = {s: {"simulation": sim[s][row], "hardware": hw[s][row]}
                     for s in sorted(set(sim) & set(hw))}
            paired.append(pairs)
            columns.append({"scenario": c, "predictor": row,
                            **judge([CROSS.margin(v) for v in pairs.values()])})
    published = sum(TUNA2013[("II", CROSS.metric)][r][c] > TUNA2013[("I", CROSS.metric)][r][c]
                    for r in CROSS.rows for c in cols)
    cause = "; ".join(x for x in (_ratio(CROSS, paired), _fallbacks(
        [*simulation, *hardware], CROSS.rows, cols)) if x)
    return Finding(CROSS, f"Tables II(b) ÷ I(b): {published}/{len(columns)} cells", published,
                   columns, cause)
