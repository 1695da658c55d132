"""The closed loop beside the open loop on the same samples of a recording: what the robot loses.

With the literature's split (TRAIN, END), the closed loop is scored at the instants of samples
TRAIN … END − 1 (:class:`rhmpc.sim.loop.metrics.MeasuredScore`). At each of those instants the
reference stands on the forecast made one sample earlier, so the open-loop figure of the same
samples is each predictor's forecast one sample ahead issued at samples TRAIN − 1 … END − 2,
the predictors fitted before the run fitted on the samples before TRAIN, as in the loop
(:func:`open_loop_beside`). Their ratio, closed over open, is what the robot loses: its tracking
of the reference between two samples, the interpolation of the forecast's points, the outlier
gate's decisions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from rhmpc.openloop.plan import OpenLoopSettings, TrackPlan, plan_track
from rhmpc.openloop.recordings import run_plan
from rhmpc.openloop.tracks import Track, poi_tracks
from rhmpc.predictors.registry import combination_members, family
from rhmpc.sim.recordings import load_recording
from rhmpc.sim.recordings.points import on_grid

__all__ = ["gap_rows", "open_loop_beside", "open_names"]


def open_names(names: Sequence[str]) -> tuple[str, ...]:
    """The predictors the open loop scores for closed-loop rows ``names``: those that forecast
    (not ``exact``), and with the combination every one of its default members, so that it is
    the closed loop's combination (:func:`rhmpc.predictors.registry.combination_members`)."""
    out = [n for n in names if n != "exact"]
    if "combination" in out:
        out.remove("combination")
        out += [m for m in combination_members() if m not in out] + ["combination"]
    return tuple(out)


def _track(data: str, read: dict) -> Track:
    """The recording's point of interest, with the other points beside it."""
    read = dict(read)
    point = read.pop("point", None)
    if point is not None:
        return poi_tracks([data], point, read)[0]
    rec = load_recording(data, **read)
    return Track(Path(data).name, rec.t, rec.z, data)


def beside_plan(data: str, read: dict, split: tuple[int, int], names: Sequence[str],
                leads: int, seed: int = 0) -> TrackPlan:
    """The plan of :func:`open_loop_beside` on ``data``: each predictor's forecast one sample
    ahead of the samples TRAIN … END − 1 (module docstring), the fitted ones fitted on the
    samples before TRAIN for ``leads`` samples (those the loop asks of them: its reference's
    points)."""
    train, end = split
    track = _track(data, read)
    wide = track.points().reshape(track.t.size, -1)
    _, wide = on_grid(track.t, wide, track.period)
    grid = wide.reshape(wide.shape[0], -1, track.z.shape[1])
    settings = OpenLoopSettings(predictors=open_names(names), leads=leads,
                                split=(train - 1, end - 1), seed=seed)
    return plan_track(track, settings, [grid[:train]],
                      where=f"frames 0–{train - 1} of {track.label}")


def open_loop_beside(plan: TrackPlan, progress: Callable[[str], None] | None = None,
                     save: Path | None = None) -> dict[str, dict]:
    """Run :func:`beside_plan`'s ``plan``, the fitted models each saved in the folder ``save``
    if given.

    Returns
    -------
    dict
        name → ``rms_error_mm``, ``max_error_mm``, ``scored`` (samples) and ``update_us``.
    """
    _, rows = run_plan(plan, progress, save)
    return {r["predictor"]: {k: r[k] for k in ("rms_error_mm", "max_error_mm", "scored",
                                               "update_us")}
            for r in rows if r["lead_samples"] == 1}


def gap_rows(docs: Sequence[dict], open_loop: dict[str, dict[str, dict]]) -> list[dict]:
    """Per closed-loop run document (``scenario``: its column, with a ``predictor``): the score
    at the measured instants, the open loop's of the same samples (``open_loop``: column →
    :func:`open_loop_beside`), their ratio, and the all-tick score against the line between
    samples."""
    out = []
    for doc in docs:
        if "error" in doc:
            continue
        name, column = doc["predictor"], doc["scenario"]
        ol = open_loop.get(column, {}).get(name, {})
        closed, opened = doc.get("rms_error_mm"), ol.get("rms_error_mm")
        ratio = closed / opened if closed is not None and opened else None
        out.append({"column": column, "predictor": name, "family": family(name),
                    "seed": doc.get("seed"), "closed_rms_mm": closed,
                    "scored_samples": doc.get("scored_samples"),
                    "open_rms_mm": opened, "closed_to_open": ratio,
                    "interpolated_rms_mm": doc.get("rms_error_interpolated_mm"),
                    "update_us": ol.get("update_us"),
                    "refresh_over_period": (doc.get("refresh_us") or {}).get("over_period")})
    return out


def gap_table(rows: Sequence[dict]) -> list[str]:
    """The rows of :func:`gap_rows` as text, one block per column, the seeds' mean per row."""
    lines = []
    for column in dict.fromkeys(r["column"] for r in rows):
        mine = [r for r in rows if r["column"] == column]
        lines += ["", f"closed loop beside open loop on {column}: RMS [mm] at the measured "
                  "instants, and the same samples forecast one sample ahead",
                  f"{'predictor':<14}{'closed loop':>12}{'open loop':>11}{'closed/open':>13}"
                  f"{'every tick, line':>18}"]
        for name in dict.fromkeys(r["predictor"] for r in mine):
            group = [r for r in mine if r["predictor"] == name]
            lines.append(f"{name:<14}" + "".join(
                f"{_mean(group, key):>{width}}" for key, width in (
                    ("closed_rms_mm", 12), ("open_rms_mm", 11), ("closed_to_open", 13),
                    ("interpolated_rms_mm", 18))))
    return lines


def _mean(group: Sequence[dict], key: str) -> str:
    values = [r[key] for r in group if r.get(key) is not None]
    return f"{np.mean(values):.3f}" if values else "—"
