"""The figure of ``rhmpc data plot``: a motion's positions per axis (the whole record, and a
zoomed window when it is long), its heart rate over time with its statistics, and its power
spectral density."""

from __future__ import annotations

import itertools
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.errors import UsageError
from rhmpc.motion.targets import PLOT_RATE
from rhmpc.motion.text import fmt
from rhmpc.sim.heart.analysis import fill_gaps, heart_rate_track, motion_stats, psd

__all__ = ["Heart", "heart_rate", "motion_figure", "plot_motion"]

#: A record no longer than this many zoom windows is drawn whole, without a zoomed window [-].
WHOLE_WINDOWS = 2.0
#: Up to this many samples an axis is drawn as a line; beyond, as its min–max per pixel [-].
LINE_POINTS = 20_000


@dataclass(frozen=True)
class Heart:
    """The heart rate a figure shows: over time, and its summary for the title."""

    t: np.ndarray
    bpm: np.ndarray
    summary: str
    how: str


def plot_motion(target, out: Path, window: float, start: float) -> None:
    """Draw ``target``'s figure (:func:`motion_figure`) over a zoomed ``window`` [s] from
    ``start`` [s] and save it to ``out`` (the format follows its suffix); a synthetic motion is
    drawn at :data:`~rhmpc.motion.targets.PLOT_RATE` at least."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    phase = getattr(target.source, "phase", None)
    rate = max(target.rate, PLOT_RATE) if phase is not None else target.rate
    n = round(target.duration * rate) + 1
    t = target.start + np.arange(n) / rate
    p = np.asarray(target.source.position(t)).reshape(n, -1) * 1e3
    with np.errstate(over="ignore", invalid="ignore"):
        stats = motion_stats(target.source, target.duration, target.rate, target.start)
    heart = heart_rate(t, p, rate, phase)
    fig = motion_figure(plt, target, t, p, rate, heart, stats, View(window, start))
    try:
        io.save_figure(fig, out, dpi=110)
    except io.FileError:
        raise
    except (OSError, ValueError) as exc:
        raise UsageError(f"{out}: cannot write the figure ({exc})") from None
    finally:
        plt.close(fig)


@dataclass(frozen=True)
class View:
    """The zoomed window of a long record: its length and its start [s]."""

    window: float
    start: float


def heart_rate(t: np.ndarray, p: np.ndarray, rate: float, phase) -> Heart:
    """The heart rate over time: a synthetic motion's own (its phase), or a recording's
    spectral estimate over 10-s stretches; the title's text is the range of what is drawn."""
    if phase is not None and hasattr(phase, "rate"):
        bpm = 60 * np.asarray(phase.rate(t), dtype=float)
        how = "the motion's heart rate"
    else:
        t, hz = heart_rate_track(t, fill_gaps(t, p), rate)
        bpm, how = 60 * hz, "spectral peak of each 10-s stretch"
    bpm_ok = bpm[np.isfinite(bpm)]
    if not bpm_ok.size:
        return Heart(t, bpm, "unknown (record shorter than 10 s)", how)
    lo, hi = float(np.min(bpm_ok)), float(np.max(bpm_ok))
    summary = f"{lo:.0f} bpm" if hi - lo < 0.5 else f"{lo:.0f}–{hi:.0f} bpm"
    return Heart(t, bpm, summary, how)


def motion_figure(plt, target, t: np.ndarray, p: np.ndarray, rate: float, heart: Heart,
            stats, args: View):
    """Positions per axis (the whole record, and a zoomed window if it is long), the heart
    rate with the statistics, and the PSD."""
    dim = p.shape[1]
    zoom = target.duration > WHOLE_WINDOWS * args.window
    height = 2.3 * dim + 4.2
    fig = plt.figure(figsize=(13, height))  # fixed margins: a layout engine costs seconds
    grid = fig.add_gridspec(dim + 2, 2, width_ratios=(2.2, 1.0),
                            height_ratios=(*([1.0] * dim), 0.6, 1.1), left=0.07, right=0.985,
                            top=1 - 0.95 / height, bottom=0.55 / height, hspace=0.6,
                            wspace=0.12)
    _plot_positions(fig, grid, target, t, p, args, zoom)
    _plot_heart_rate(fig.add_subplot(grid[dim, 0]), target, heart)
    _plot_stats(fig.add_subplot(grid[dim, 1]), stats, dim)
    _plot_psd(fig.add_subplot(grid[dim + 1, :]), *psd(fill_gaps(t, p), rate, resolution=0.02),
              rate, stats)
    fig.suptitle(f"{target.name}: p-p {stats.peak_to_peak * 1e3:.2f} mm, "
                 f"RMS {stats.rms * 1e3:.2f} mm, heart rate {heart.summary}, "
                 f"{fmt(target.rate)} Hz, {fmt(target.duration)} s\n"
                 + "\n".join(textwrap.wrap(target.description, 170)), fontsize=10)
    return fig


def _plot_positions(fig, grid, target, t: np.ndarray, p: np.ndarray,
                    args: View, zoom: bool) -> None:
    """Per axis: the whole record (full width when short), and a zoomed window when long."""
    dim = p.shape[1]
    labels = ("x", "y", "z") if dim == 3 else ("x",)
    end = target.start + target.duration
    w0 = min(max(args.start, target.start), max(end - args.window, target.start))
    inside = (t >= w0) & (t <= w0 + args.window)
    for d in range(dim):
        ax = fig.add_subplot(grid[d, 0] if zoom else grid[d, :])
        band = _draw_trace(ax, t, p[:, d], 1000 if zoom else 1400)
        ax.set_ylabel(f"{labels[d]} [mm]")
        ax.set_xlim(target.start, end)
        if d == 0:
            ax.set_title("position, the whole record" + (" (min–max per pixel)" if band else ""))
        if d == dim - 1:
            ax.set_xlabel("time [s]")
        if not zoom:
            continue
        ax.axvspan(w0, w0 + args.window, color="tab:orange", alpha=0.15, lw=0)
        axz = fig.add_subplot(grid[d, 1])
        axz.plot(t[inside], p[inside, d], lw=0.9, color="tab:blue")
        axz.set_xlim(w0, w0 + args.window)
        if d == 0:
            axz.set_title(f"{fmt(args.window)} s from {fmt(w0)} s")
        if d == dim - 1:
            axz.set_xlabel("time [s]")


def _draw_trace(ax, t: np.ndarray, y: np.ndarray, pixels: int) -> bool:
    """``y`` over ``t`` as a line, or as its min–max over each of ``pixels`` columns when it
    has more than :data:`LINE_POINTS` samples (which a line would draw the same, slowly).
    Returns whether it drew the min–max band."""
    if t.size <= LINE_POINTS:
        ax.plot(t, y, lw=0.6, color="tab:blue")
        return False
    edges = np.linspace(0, t.size, pixels + 1).astype(int)
    lo = np.full(pixels, np.nan)
    hi = np.full(pixels, np.nan)
    for i, (a, b) in enumerate(itertools.pairwise(edges)):
        seg = y[a:b][np.isfinite(y[a:b])]
        if seg.size:
            lo[i], hi[i] = seg.min(), seg.max()
    mid = t[np.minimum((edges[:-1] + edges[1:]) // 2, t.size - 1)]
    ax.fill_between(mid, lo, hi, color="tab:blue", lw=0.6, edgecolor="tab:blue", step="mid")
    return True


def _plot_heart_rate(ax, target, heart: Heart) -> None:
    """The heart rate over time, as the title states it."""
    if not heart.t.size:
        ax.axis("off")
        ax.text(0.0, 0.5, f"heart rate {heart.summary}", transform=ax.transAxes)
        return
    ax.plot(heart.t, heart.bpm, color="tab:red", lw=1.0, marker="" if heart.t.size > 60
            else ".")
    ax.set_xlim(target.start, target.start + target.duration)
    ax.set_ylabel("heart rate\n[beats/min]")
    ax.set_xlabel("time [s]")
    ax.set_title(f"heart rate: {heart.how}", fontsize=9)


def _plot_stats(ax, stats, dim: int) -> None:
    """The statistics as text."""
    ax.axis("off")
    ax.text(0.0, 1.0, "\n".join([
        f"peak-to-peak  {stats.peak_to_peak * 1e3:.2f} mm (largest axis range)",
        f"RMS           {stats.rms * 1e3:.2f} mm (about the mean"
        + (", 3-D)" if dim > 1 else ")"),
        "spectral peaks " + (", ".join(f"{v:.2f}" for v in stats.peaks[:6]) or "none")
        + (" Hz" if len(stats.peaks) else ""),
    ]), transform=ax.transAxes, va="top", family="monospace", fontsize=8)


def _plot_psd(ax, f: np.ndarray, s: np.ndarray, rate: float, stats) -> None:
    """The Welch PSD per axis, the spectral peaks marked."""
    dim = s.shape[1]
    labels = ("x", "y", "z") if dim == 3 else ("x",)
    for d in range(dim):
        ax.semilogy(f, s[:, d], lw=0.9, label=labels[d])
    ax.set_xlim(0, min(30.0, rate / 2))
    top = float(np.max(s)) if np.isfinite(np.max(s)) and np.max(s) > 0 else 1.0
    ax.set_ylim(max(top * 1e-9, 1e-12), top * 5)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD [mm²/Hz]")
    ax.set_title("power spectral density (Welch)")
    ax.legend(loc="upper right", ncols=dim)
    for fp in stats.peaks[:6]:
        ax.axvline(fp, color="0.5", lw=0.5, ls=":")
