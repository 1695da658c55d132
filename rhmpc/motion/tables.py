"""The tables of ``rhmpc data``: what each scenario replicates (from its specification alone),
and the statistics measured on a motion (mm, Hz, beats/min), as rows and as text."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import numpy as np

from rhmpc.motion.targets import Request, Target, resolve
from rhmpc.motion.text import fmt, mm
from rhmpc.sim.heart import SPECS
from rhmpc.sim.heart.analysis import motion_stats, predictability
from rhmpc.sim.heart.specs import ScenarioSpec
from rhmpc.sim.recordings import RecordedMotion, coverage, coverage_lines

__all__ = ["measured_rows", "measured_table", "show_lines", "spec_row", "spec_table",
           "stats_row"]

#: The width of the tables' text [characters].
TABLE_WIDTH = 100



def stats_row(target: Target) -> dict:
    """The statistics of ``target`` (mm, Hz, beats/min) as a JSON-friendly dict."""
    with np.errstate(over="ignore", invalid="ignore"):  # outliers: the reader has warned
        stats = motion_stats(target.source, target.duration, target.rate, target.start)
        value = predictability(target.source, target.duration, target.start)
    row = {"name": target.name, "dim": int(target.source.dim),
           "sensor_rate_hz": float(fmt(target.rate, 6)),
           "duration_s": round(target.duration, 3)}
    row.update(stats.as_dict())
    if isinstance(target.source, RecordedMotion):  # the file's own samples, as the reader counts
        row.update(coverage(target.source, target.start, target.duration))
    row["predictability"] = None if not np.isfinite(value) else round(value, 4)
    row["description"] = target.description
    return row


def spec_row(spec: ScenarioSpec) -> dict:
    """What a scenario replicates, from its specification alone (no synthesis)."""
    return {"name": spec.name, "dim": spec.dim, "sensor_rate_hz": spec.sensor_rate,
            "duration_s": spec.duration,
            "target_peak_to_peak_mm": round(spec.peak_to_peak * 1e3, 3),
            "target_rms_mm": None if spec.rms is None else round(spec.rms * 1e3, 3),
            "heart": _heart_text(spec), "reported": list(spec.reported),
            "description": spec.description}


def _heart_text(spec: ScenarioSpec) -> str:
    """The heart rate a scenario is built with, in words."""
    from rhmpc.sim.heart.rr import STAIRCASE_LEVELS_HZ

    variation = " + HRV" if spec.variable and spec.heart in ("constant", "staircase") else ""
    if spec.heart == "staircase":
        lo, hi = 60 * min(STAIRCASE_LEVELS_HZ), 60 * max(STAIRCASE_LEVELS_HZ)
        return f"staircase {lo:.0f}–{hi:.0f}{variation}"
    if spec.heart == "record":
        return f"beats of {Path(str(spec.record)).parent.name or spec.record}"
    if spec.heart == "invivo":
        return f"{60 * spec.heart_rate:.0f}, beat to beat varying"
    return f"{60 * spec.heart_rate:.0f}{variation}"


def spec_table(rows: list[dict]) -> list[str]:
    """The table of :func:`spec_row` rows, each with its description below."""
    lines = [f"{'name':<16} {'dim':>3} {'rate':>6} {'dur':>6} {'p-p':>7} {'RMS':>6}  "
             "heart rate",
             f"{'':<16} {'':>3} {'[Hz]':>6} {'[s]':>6} {'[mm]':>7} {'[mm]':>6}  [beats/min]"]
    for r in rows:
        rms = "—" if r["target_rms_mm"] is None else f"{r['target_rms_mm']:.2f}"
        lines.append(f"{r['name']:<16} {r['dim']:>3} {r['sensor_rate_hz']:>6g} "
                     f"{r['duration_s']:>6g} {r['target_peak_to_peak_mm']:>7.2f} {rms:>6}  "
                     f"{r['heart']}")
        lines += textwrap.wrap(r["description"], TABLE_WIDTH, initial_indent=" " * 18,
                               subsequent_indent=" " * 18)
    lines.append("p-p and RMS: the calibration targets (— keeps the shape's own RMS). All "
                 "scenarios are synthetic.")
    lines.append("Measured statistics: rhmpc data list --measure (all, several seconds), "
                 "rhmpc data show NAME (one).")
    return lines


def measured_rows(names: list[str], req: Request) -> list[dict]:
    """Each scenario's measured statistics beside its targets, with progress on stderr."""
    from tqdm import tqdm

    rows = []
    with tqdm(names, desc="measuring", unit="scenario", leave=False, file=sys.stderr,
              mininterval=0.5) as bar:
        for name in bar:
            bar.set_postfix_str(name)
            row = stats_row(resolve(name, req))
            spec = SPECS[name]
            row["target_peak_to_peak_mm"] = round(spec.peak_to_peak * 1e3, 3)
            row["target_rms_mm"] = None if spec.rms is None else round(spec.rms * 1e3, 3)
            rows.append(row)
    return rows


def measured_table(rows: list[dict]) -> list[str]:
    """The table of measured statistics beside the targets."""
    lines = [f"{'name':<16} {'dim':>3} {'rate':>6} {'dur':>6} {'p-p':>7} {'(target)':>9} "
             f"{'RMS':>6} {'(target)':>9} {'HR bpm':>12} {'predict.':>8}",
             f"{'':<16} {'':>3} {'[Hz]':>6} {'[s]':>6} {'[mm]':>7} {'':>9} {'[mm]':>6} "
             f"{'':>9} {'':>12} {'RLS/hold':>8}"]
    for r in rows:
        rms_t = "—" if r["target_rms_mm"] is None else f"{r['target_rms_mm']:.2f}"
        lines.append(f"{r['name']:<16} {r['dim']:>3} {r['sensor_rate_hz']:>6g} "
                     f"{fmt(r['duration_s']):>6} {r['peak_to_peak_mm']:>7.2f} "
                     f"{r['target_peak_to_peak_mm']:>9.2f} {r['rms_mm']:>6.2f} {rms_t:>9} "
                     f"{_bpm_text(r['heart_rate_bpm']):>12} {_pred_text(r):>8}")
    lines.append("All scenarios are synthetic, calibrated to the papers' reported statistics "
                 "(invivo-video: to an in-vivo recording's).")
    lines.append("predict.: one-step RLS / hold RMS error 120 ms (3 samples) ahead at 25 Hz on "
                 "the noise-free motion (line spectrum ≈ 0; mechanical phantom ≈ 0.12; in-vivo "
                 "≈ 0.69).")
    return lines


def _bpm_text(hr: list) -> str:
    """A heart-rate range [beats/min] as ``100`` or ``92–108``; — when unknown."""
    if hr[0] is None:
        return "—"
    return f"{hr[0]:.0f}" if abs(hr[1] - hr[0]) < 0.5 else f"{hr[0]:.0f}–{hr[1]:.0f}"


def show_lines(row: dict) -> list[str]:
    """``data show``'s lines for a :func:`stats_row` row."""
    hr = row["heart_rate_bpm"]
    hr_text = ("— (not estimable: too few complete samples, or values not finite)"
               if hr[0] is None
               else f"{hr[0]:.1f}–{hr[1]:.1f} beats/min" if abs(hr[1] - hr[0]) >= 0.05
               else f"{hr[0]:.1f} beats/min")
    if hr[0] is not None and row["description"].startswith("recording"):
        hr_text += " (the spectral peak)"
    peaks = ", ".join(f"{v:.2f}" for v in row["spectral_peaks_hz"])
    lines = [
        f"{row['name']}: {row['description']}",
        f"  axes              {row['dim']}",
        f"  sample rate       {fmt(row['sensor_rate_hz'])} Hz",
        f"  duration          {fmt(row['duration_s'])} s",
        f"  peak-to-peak      {mm(row['peak_to_peak_mm'])} mm (largest per-axis range)",
        f"  RMS               {mm(row['rms_mm'])} mm (about the mean"
        + (", 3-D)" if row["dim"] > 1 else ")"),
        "  RMS per axis      " + ", ".join(mm(v) for v in row["rms_per_axis_mm"]) + " mm",
        f"  heart rate        {hr_text}",
        f"  spectral peaks    {peaks or 'none'}" + (" Hz" if peaks else ""),
    ]
    lines += coverage_lines(row)
    lines.append(f"  predictability    {_pred_text(row)} (one-step RLS / hold RMS error, 120 ms "
                 "ahead at 25 Hz; phantom ≈ 0.12, in-vivo heart ≈ 0.69)")
    return lines


def _pred_text(row: dict) -> str:
    value = row.get("predictability")
    return "—" if value is None else f"{value:.3f}"
