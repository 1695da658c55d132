"""The objective of a sweep against its parameters: a panel per parameter (each point's mean
± sd), and a heat map over two parameters when the sweep varies two (``rhmpc tune --plot``)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from rhmpc import io
from rhmpc.errors import UsageError
from rhmpc.tuning.objective import Objective
from rhmpc.tuning.report import PointSummary, best, format_value, parameter_keys


def _numeric(values: Sequence[Any]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


#: Distinct values up to which an axis is ticked at the values themselves.
MAX_VALUE_TICKS = 8


def log_spaced(values: Sequence[Any]) -> bool:
    """Whether positive numbers are better shown on a log axis: they span a factor of 20 or
    more, or their logarithms are more evenly spaced than the values themselves."""
    if not values or not _numeric(values):
        return False
    v = np.unique(np.asarray(values, dtype=float))
    if v.size < 2 or v[0] <= 0:
        return False
    if v[-1] / v[0] >= 20:
        return True
    if v.size < 3 or v[-1] / v[0] < 3:
        return False

    def spread(x: np.ndarray) -> float:
        d = np.diff(x)
        return float(np.std(d) / np.mean(d))

    return spread(np.log(v)) < spread(v)


def _value_axis(ax, which: str, values: Sequence[float], log: bool) -> None:
    """A numeric axis (``which``: ``"x"`` or ``"y"``): log where asked, readable ticks.

    Few distinct values are ticked at the values; a log axis over more gets ticks at 1, 2 and
    5 of every decade when it spans three decades or less, plain numbers throughout.
    """
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    v = np.unique(np.asarray(values, dtype=float))
    axis = ax.xaxis if which == "x" else ax.yaxis
    if log:
        (ax.set_xscale if which == "x" else ax.set_yscale)("log")
    plain = FuncFormatter(lambda x, _pos: f"{x:.3g}")
    if v.size <= MAX_VALUE_TICKS:
        axis.set_major_locator(FixedLocator(v))
    elif log:
        decades = np.log10(v[-1] / v[0])
        axis.set_major_locator(LogLocator(10, subs=(1.0, 2.0, 5.0) if decades <= 3 else (1.0,)))
    else:
        return
    axis.set_major_formatter(plain)
    axis.set_minor_formatter(NullFormatter())


def _log_axis(values: Sequence[Any], sampled_log: bool) -> bool:
    """A log axis for positive numbers sampled on a log scale or log-spaced."""
    if not values or not _numeric(values) or min(values) <= 0:
        return False
    return sampled_log or log_spaced(values)


def _positions(values: Sequence[Any]) -> tuple[np.ndarray, list[str] | None]:
    """x positions of parameter values: the numbers, or indices of categorical labels."""
    if _numeric(values):
        return np.asarray(values, dtype=float), None
    labels = list(dict.fromkeys(format_value(v) for v in values))
    return np.asarray([labels.index(format_value(v)) for v in values], dtype=float), labels


def _varied_keys(shown: Sequence[PointSummary]) -> list[str]:
    keys = parameter_keys(shown)
    return [k for k in keys if len({json.dumps(s.parameters.get(k)) for s in shown}) > 1] or keys


def plot_objective(summaries: Sequence[PointSummary], objective: Objective, path: str | Path,
                   title: str = "", log_keys: Iterable[str] | None = None) -> None:
    """Write :func:`objective_figure` to ``path`` (PNG, PDF, SVG...)."""
    import matplotlib.pyplot as plt

    fig = objective_figure(summaries, objective, title, log_keys)
    io.save_figure(fig, path, dpi=120)
    plt.close(fig)


def objective_figure(summaries: Sequence[PointSummary], objective: Objective, title: str = "",
                     log_keys: Iterable[str] | None = None):
    """One panel per parameter: each point's mean objective (± sd) against its value; for a
    sweep of two parameters, a heat map of the objective over both as well.

    Parameters
    ----------
    summaries : sequence of PointSummary
        The ranked points (:func:`summarize`).
    objective : Objective
        What was minimised (the y label).
    title : str
        The figure's title.
    log_keys : iterable of str, optional
        Parameters sampled on a log scale (the spec's ``scale = "log"``); others are put on a
        log axis when their values are log-spaced (:func:`log_spaced`).

    Returns
    -------
    matplotlib.figure.Figure
        The figure (Agg backend).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [s for s in summaries if math.isfinite(s.score_mean)]
    keys = _varied_keys(shown)
    if not shown or not keys:
        raise UsageError("nothing to plot: no successful evaluation with varied parameters")
    log = {k: _log_axis([s.parameters[k] for s in shown if k in s.parameters],
                        k in set(log_keys or ())) for k in keys}
    heat = len(keys) == 2
    panels = len(keys) + heat
    fig, axes = plt.subplots(1, panels, figsize=(4.2 * panels + 0.6 + heat, 3.8),
                             squeeze=False, constrained_layout=True)
    ylabel = objective.metric if not objective.penalties else "objective"
    top = best(shown)
    for ax, key in zip(axes[0], keys, strict=False):
        _panel(ax, key, shown, top, log[key], ylabel, joined=len(keys) == 1)
    if heat:
        _heat_map(fig, axes[0][-1], keys, shown, top, log, ylabel)
    handles, labels = axes[0][0].get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    axes[0][0].legend(unique.values(), unique.keys(), fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def _panel(ax, key: str, shown: Sequence[PointSummary], top: PointSummary | None, log: bool,
           ylabel: str, joined: bool) -> None:
    """The objective against one parameter: mean ± sd per point, best and base marked."""
    pts = [s for s in shown if key in s.parameters]
    values = [s.parameters[key] for s in pts]
    x, labels = _positions(values)
    if labels is None:
        _value_axis(ax, "x", x, log)
    else:
        ax.set_xticks(range(len(labels)), labels, rotation=30, ha="right")
    y = np.asarray([s.score_mean for s in pts])
    e = np.asarray([s.score_std for s in pts])
    feasible = np.asarray([s.status in ("ok", "incomplete") for s in pts])
    ax.errorbar(x[feasible], y[feasible], yerr=e[feasible], fmt="o", ms=4, capsize=2,
                alpha=0.8, label="points (mean ± sd)")
    if (~feasible).any():
        ax.plot(x[~feasible], y[~feasible], "x", color="0.5", label="infeasible/failed")
    if joined and feasible.sum() > 1:  # a 1-D sweep: join the points
        order = np.argsort(x[feasible])
        ax.plot(x[feasible][order], y[feasible][order], "-", color="C0", alpha=0.5)
    for s, xi, yi in zip(pts, x, y, strict=True):
        if s is top:
            ax.plot(xi, yi, "*", ms=14, color="C3", label="best")
        if s.base:
            ax.plot(xi, yi, "s", ms=9, mfc="none", color="k", label="base")
    ax.set_xlabel(key)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.3)


def _heat_map(fig, ax, keys: Sequence[str], shown: Sequence[PointSummary],
              top: PointSummary | None, log: dict[str, bool], label: str) -> None:
    """The objective over two parameters: grid cells (each value pair once) annotated with
    their mean, or points coloured by it (a random or Latin-hypercube sweep)."""
    pts = [s for s in shown if all(k in s.parameters for k in keys)]
    xs, ys = ([s.parameters[k] for s in pts] for k in keys)
    fx, fy = (list(dict.fromkeys(format_value(v) for v in vs)) for vs in (xs, ys))
    pairs = {(format_value(a), format_value(b)) for a, b in zip(xs, ys, strict=True)}
    z = np.asarray([s.score_mean for s in pts])
    if len(pairs) == len(pts) and len(fx) * len(fy) <= 4 * len(pts):
        _grid_cells(fig, ax, keys, pts, xs, ys, z, top, label)
    else:
        x, lx = _positions(xs)
        y, ly = _positions(ys)
        art = ax.scatter(x, y, c=z, cmap="viridis_r", s=30, edgecolors="k", linewidths=0.3)
        for which, v, labels, key in (("x", x, lx, keys[0]), ("y", y, ly, keys[1])):
            if labels is None:
                _value_axis(ax, which, v, log[key])
        if top in pts:
            i = pts.index(top)
            ax.plot(x[i], y[i], "*", ms=16, mfc="none", mec="C3", mew=1.5)
        fig.colorbar(art, ax=ax, label=label)
    ax.set_xlabel(keys[0])
    ax.set_ylabel(keys[1])
    ax.set_title("objective over both parameters", fontsize=9)


def _sorted_labels(values: Sequence[Any]) -> list[str]:
    """Distinct values as labels, in numeric order where they are numbers."""
    unique = list({format_value(v): v for v in values}.items())
    if _numeric([v for _, v in unique]):
        unique.sort(key=lambda item: float(item[1]))
    return [label for label, _ in unique]


def _grid_cells(fig, ax, keys, pts, xs, ys, z, top, label: str) -> None:
    """A grid sweep's heat map: one cell per value pair, equal cells (log-spaced values are
    evenly spaced), infeasible cells hatched, the best one outlined."""
    lx, ly = _sorted_labels(xs), _sorted_labels(ys)
    grid = np.full((len(ly), len(lx)), np.nan)
    bad = np.zeros_like(grid, dtype=bool)
    where = {}
    for s, a, b, v in zip(pts, xs, ys, z, strict=True):
        i, j = ly.index(format_value(b)), lx.index(format_value(a))
        grid[i, j], bad[i, j], where[id(s)] = v, s.status not in ("ok", "incomplete"), (j, i)
    art = ax.imshow(np.ma.masked_invalid(grid), origin="lower", cmap="viridis_r",
                    aspect="auto")
    fig.colorbar(art, ax=ax, label=label)
    finite = grid[np.isfinite(grid)]
    middle = (finite.min() + finite.max()) / 2 if finite.size else 0.0
    if grid.size <= 100:
        for (i, j), v in np.ndenumerate(grid):
            if np.isfinite(v):
                ax.text(j, i, f"{v:.3g}", ha="center", va="center", fontsize=7,
                        color="k" if v < middle else "w")
    for i, j in zip(*np.nonzero(bad), strict=True):
        ax.add_patch(_hatch(j, i))
    if top is not None and id(top) in where:
        ax.add_patch(_outline(*where[id(top)]))
    ax.set_xticks(range(len(lx)), lx, rotation=30, ha="right")
    ax.set_yticks(range(len(ly)), ly)


def _outline(x: float, y: float):
    from matplotlib.patches import Rectangle

    return Rectangle((x - 0.5, y - 0.5), 1, 1, fill=False, edgecolor="C3", linewidth=2.5)


def _hatch(x: float, y: float):
    from matplotlib.patches import Rectangle

    return Rectangle((x - 0.5, y - 0.5), 1, 1, fill=False, hatch="xx", edgecolor="0.4",
                     linewidth=0)
