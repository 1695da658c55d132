"""`rhmpc data`: list, show, export and plot heart-motion scenarios and recordings.

``rhmpc data list``                 the named scenarios with their statistics
``rhmpc data show NAME``            p-p, RMS, heart-rate range, spectral peaks, predictability
``rhmpc data export NAME FILE``     write the motion (or a sensor's samples) to .csv/.npz
``rhmpc data plot NAME FILE.png``   position per axis over time and its PSD (Tuna Fig. 2)

NAME is a scenario name or the path of a recording (.csv/.npz/.mat; for .mat: ``--var``,
``--rows``/``--cols``, ``--rate``, ``--units``). Millimetres appear only here.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc.errors import UsageError
from sim.heart import DEFAULT_SCENARIO, SCENARIOS, SPECS, make_scenario
from sim.heart.analysis import fill_gaps, motion_stats, predictability, psd
from sim.heart.invivo import source_statistics, statistics_table
from sim.heart.motion import MotionSource
from sim.heart.scenarios import DEFAULT_SEED, missing_data
from sim.recordings import export_source, load_recording, parse_indices, save_recording
from sim.sensors import SENSORS, sensor_from_name


@dataclass(frozen=True)
class _Target:
    """What the CLI works on: a source with its natural rate and duration."""

    name: str
    source: MotionSource
    rate: float
    duration: float
    description: str
    start: float = 0.0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``rhmpc data`` and its actions."""
    parser = subparsers.add_parser(
        "data", help="list, show, export and plot heart-motion scenarios",
        description="Heart-motion scenarios (synthetic replicas of the papers' data sets) "
        "and recordings: statistics, export and figures.")
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--seed", type=int, default=DEFAULT_SEED,
                        help="seed of the beat-to-beat variability (default %(default)s)")
    common.add_argument("--duration", type=float, help="seconds to use (default: the scenario's)")
    common.add_argument("--bpm", type=float, help="constant heart rate [beats/min]")
    common.add_argument("--record", help="PhysioNet record whose annotated beats drive the "
                        "heart: a shipped name (mitdb-100, 1003) or a path without extension")
    common.add_argument("--var", help="MATLAB variable holding the positions (.mat files)")
    common.add_argument("--rows", type=parse_indices, help="0-based rows holding x,y,z (.mat)")
    common.add_argument("--cols", type=parse_indices, help="0-based columns holding x,y,z (.mat)")
    common.add_argument("--units", choices=("mm", "m", "um", "cm"),
                        help="length unit when the file does not state it (default mm)")

    p_list = actions.add_parser("list", parents=[common], help="scenarios and their statistics")
    p_list.add_argument("--json", action="store_true", help="machine-readable output")

    p_show = actions.add_parser("show", parents=[common], help="statistics of one scenario/file")
    p_show.add_argument("name", nargs="?", default=DEFAULT_SCENARIO,
                        help=f"scenario or recording file (default {DEFAULT_SCENARIO})")
    p_show.add_argument("--json", action="store_true", help="machine-readable output")
    p_show.add_argument("--rate", type=float, help="sample rate of a .mat file without a time "
                        "vector [Hz]")

    p_exp = actions.add_parser("export", parents=[common], help="write a scenario to .csv/.npz")
    p_exp.add_argument("name", help="scenario or recording file")
    p_exp.add_argument("file", help="output .csv (s, mm) or .npz (s, m)")
    p_exp.add_argument("--rate", type=float, help="sample rate [Hz] (default: the sensor's; for "
                       "a .mat file without a time vector also its rate)")
    p_exp.add_argument("--sensor", choices=SENSORS,
                       help="write this sensor's noisy samples instead of the true motion")
    p_exp.add_argument("--force", action="store_true", help="overwrite an existing file")

    p_plot = actions.add_parser("plot", parents=[common], help="figure: position and PSD")
    p_plot.add_argument("name", help="scenario or recording file")
    p_plot.add_argument("file", help="output image (.png, .pdf, .svg)")
    p_plot.add_argument("--rate", type=float, help="sample rate of a .mat file without a time "
                        "vector [Hz]")
    p_plot.add_argument("--window", type=float, default=10.0,
                        help="length of the zoomed time window [s] (default %(default)s)")
    p_plot.add_argument("--start", type=float, default=0.0,
                        help="start of the zoomed window [s] (default %(default)s)")
    parser.set_defaults(func=run, action=None)


def run(args: argparse.Namespace) -> int:
    """Dispatch to the action."""
    if args.action is None:
        raise UsageError("choose an action: list, show, export or plot")
    return {"list": _list, "show": _show, "export": _export, "plot": _plot}[args.action](args)


def _target(name: str, args: argparse.Namespace) -> _Target:
    """Resolve NAME to a scenario (with the command-line overrides) or a recording."""
    overrides: dict = {}
    if args.bpm is not None:
        if not args.bpm > 0:
            raise UsageError(f"--bpm must be positive, got {args.bpm}")
        overrides["heart_rate"] = args.bpm / 60.0
    if args.record is not None:
        overrides["record"] = args.record
    if args.duration is not None:
        if not args.duration > 0:
            raise UsageError(f"--duration must be positive, got {args.duration}")
        overrides["duration"] = args.duration
    if name in SPECS:
        sc = make_scenario(name, np.random.default_rng(args.seed), **overrides)
        return _Target(sc.name, sc.source, sc.sensor_rate, sc.duration, sc.description)
    path = Path(name)
    if path.suffix.lower() in {".csv", ".npz", ".txt", ".mat"} or path.exists():
        if args.bpm is not None or args.record is not None:
            raise UsageError("--bpm and --record apply to scenarios, not recordings")
        rec = load_recording(path, **_read_options(args, path))
        duration = rec.duration if args.duration is None else min(args.duration, rec.duration)
        return _Target(path.name, rec, rec.sample_rate, duration, f"recording {path}",
                       float(rec.t[0]))
    raise UsageError(f"unknown scenario {name!r}; valid names: {', '.join(SCENARIOS)} "
                     "(or the path of a .csv/.npz recording)")



def _read_options(args: argparse.Namespace, path: Path) -> dict:
    """``load_recording`` keywords: --units always, --var/--rows/--cols/--rate for .mat."""
    out = {"units": args.units} if getattr(args, "units", None) else {}
    if path.suffix.lower() == ".mat":
        for key in ("var", "rows", "cols", "rate"):
            if getattr(args, key, None) is not None:
                out[key] = getattr(args, key)
    elif any(getattr(args, k, None) is not None for k in ("var", "rows", "cols")):
        raise UsageError("--var, --rows and --cols apply to .mat files")
    return out


def _stats_row(target: _Target) -> dict:
    stats = motion_stats(target.source, target.duration, target.rate, target.start)
    row = {"name": target.name, "dim": int(target.source.dim),
           "sensor_rate_hz": target.rate, "duration_s": round(target.duration, 3)}
    row.update(stats.as_dict())
    value = predictability(target.source, target.duration, target.start)
    row["predictability"] = None if not np.isfinite(value) else round(value, 4)
    row["description"] = target.description
    return row


def _list(args: argparse.Namespace) -> int:
    rows = []
    for name in SCENARIOS:
        if (missing := missing_data(name)) is not None:
            print(f"# {name}: skipped, needs {missing}", file=sys.stderr)
            continue
        row = _stats_row(_target(name, args))
        spec = SPECS[name]
        row["target_peak_to_peak_mm"] = round(spec.peak_to_peak * 1e3, 3)
        row["target_rms_mm"] = None if spec.rms is None else round(spec.rms * 1e3, 3)
        rows.append(row)
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    head = (f"{'name':<16} {'dim':>3} {'rate':>6} {'dur':>6} {'p-p':>7} {'(target)':>9} "
            f"{'RMS':>6} {'(target)':>9} {'HR bpm':>12} {'predict.':>8}")
    print(head)
    print(f"{'':<16} {'':>3} {'[Hz]':>6} {'[s]':>6} {'[mm]':>7} {'':>9} {'[mm]':>6} {'':>9} "
          f"{'':>12} {'RLS/hold':>8}")
    for r in rows:
        hr = r["heart_rate_bpm"]
        hr_text = f"{hr[0]:.0f}" if abs(hr[1] - hr[0]) < 0.5 else f"{hr[0]:.0f}–{hr[1]:.0f}"
        rms_t = "—" if r["target_rms_mm"] is None else f"{r['target_rms_mm']:.2f}"
        print(f"{r['name']:<16} {r['dim']:>3} {r['sensor_rate_hz']:>6g} {r['duration_s']:>6g} "
              f"{r['peak_to_peak_mm']:>7.2f} {r['target_peak_to_peak_mm']:>9.2f} "
              f"{r['rms_mm']:>6.2f} {rms_t:>9} {hr_text:>12} {_pred_text(r):>8}")
    print("All scenarios are synthetic, calibrated to the papers' reported statistics "
          "(invivo-video: to an in-vivo recording's).")
    print("predict.: one-step RLS / hold RMS error 120 ms (3 samples) ahead at 25 Hz on the "
          "noise-free motion (line spectrum ≈ 0; mechanical phantom ≈ 0.12; in-vivo ≈ 0.69).")
    return 0


def _show(args: argparse.Namespace) -> int:
    target = _target(args.name, args)
    row = _stats_row(target)
    invivo = args.name in SPECS and SPECS[args.name].heart == "invivo"
    if invivo:  # the in-vivo regime beside the recording it was built from
        row["regime"] = source_statistics(target.source, target.duration)
    if args.json:
        print(json.dumps(row, indent=2))
        return 0
    hr = row["heart_rate_bpm"]
    print(f"{row['name']}: {row['description']}")
    print(f"  axes              {row['dim']}")
    print(f"  sample rate       {row['sensor_rate_hz']:g} Hz")
    print(f"  duration          {row['duration_s']:g} s")
    print(f"  peak-to-peak      {row['peak_to_peak_mm']:.3f} mm (largest per-axis range)")
    print(f"  RMS               {row['rms_mm']:.3f} mm (about the mean"
          + (", 3-D)" if row["dim"] > 1 else ")"))
    print("  RMS per axis      " + ", ".join(f"{v:.3f}" for v in row["rms_per_axis_mm"]) + " mm")
    print(f"  heart rate        {hr[0]:.1f}–{hr[1]:.1f} beats/min")
    peaks = ", ".join(f"{v:.2f}" for v in row["spectral_peaks_hz"])
    print(f"  spectral peaks    {peaks or 'none'}" + (" Hz" if peaks else ""))
    if row["missing_fraction"]:
        print(f"  missing samples   {100 * row['missing_fraction']:.2f} %")
    print(f"  predictability    {_pred_text(row)} (one-step RLS / hold RMS error, 120 ms ahead "
          "at 25 Hz; phantom ≈ 0.12, in-vivo heart ≈ 0.69)")
    if invivo:
        print("  the in-vivo recording's statistics (sim.heart.invivo, sampled at 25 Hz):")
        print("\n".join(statistics_table(row["regime"])))
    return 0


def _pred_text(row: dict) -> str:
    value = row.get("predictability")
    return "—" if value is None else f"{value:.3f}"


def _export(args: argparse.Namespace) -> int:
    target = _target(args.name, args)
    out = Path(args.file)
    if out.suffix.lower() not in {".csv", ".npz"}:
        raise UsageError(f"{out}: output must end in .csv or .npz")
    if out.exists() and not args.force:
        raise UsageError(f"{out} exists; pass --force to overwrite")
    rate = target.rate if args.rate is None else args.rate
    if not rate > 0:
        raise UsageError(f"--rate must be positive, got {rate}")
    comment = f"rhmpc {target.name}: {target.description}"
    if args.sensor:
        sensor = sensor_from_name(args.sensor, rate=args.rate, dim=int(target.source.dim))
        stream = sensor.measure(target.source, target.duration, np.random.default_rng(args.seed),
                                t0=target.start)
        save_recording(out, stream.t, stream.z, comment + f"; measured by {sensor.name}")
        n = len(stream)
    else:
        export_source(target.source, out, target.duration, rate, target.start, comment)
        n = round(target.duration * rate) + 1
    print(f"wrote {n} samples of {target.name} to {out}")
    return 0


def _plot(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    target = _target(args.name, args)
    if not args.window > 0:
        raise UsageError(f"--window must be positive, got {args.window}")
    phase = getattr(target.source, "phase", None)
    # a synthetic truth is drawn at ≥ 250 Hz so slow sensors (28 Hz) still show its shape
    rate = max(target.rate, 250.0) if phase is not None else target.rate
    n = round(target.duration * rate) + 1
    t = target.start + np.arange(n) / rate
    p = np.asarray(target.source.position(t)).reshape(n, -1) * 1e3
    stats = motion_stats(target.source, target.duration, target.rate, target.start)
    dim = p.shape[1]
    height = 2.3 * dim + 4.2
    fig = plt.figure(figsize=(13, height))  # fixed margins: a layout engine costs seconds
    grid = fig.add_gridspec(dim + 2, 2, width_ratios=(2.2, 1.0),
                            height_ratios=(*([1.0] * dim), 0.6, 1.1), left=0.07, right=0.985,
                            top=1 - 0.95 / height, bottom=0.55 / height, hspace=0.6,
                            wspace=0.12)
    _plot_positions(fig, grid, target, t, p, rate, args)
    _plot_rate_and_stats(fig, grid[dim, 0], grid[dim, 1], target, t, phase, stats, dim)
    _plot_psd(fig.add_subplot(grid[dim + 1, :]), *psd(fill_gaps(t, p), rate, resolution=0.02),
              rate, stats)
    hr = stats.heart_rate
    hr_text = (f"{60 * hr[0]:.0f} bpm" if abs(hr[1] - hr[0]) * 60 < 0.5
               else f"{60 * hr[0]:.0f}–{60 * hr[1]:.0f} bpm")
    fig.suptitle(f"{target.name}: p-p {stats.peak_to_peak * 1e3:.2f} mm, "
                 f"RMS {stats.rms * 1e3:.2f} mm, heart rate {hr_text}, "
                 f"{target.rate:g} Hz, {target.duration:g} s\n{target.description}",
                 fontsize=10)
    out = Path(args.file)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    print(f"wrote {out}")
    return 0


def _plot_positions(fig, grid, target: _Target, t: np.ndarray, p: np.ndarray, rate: float,
                    args: argparse.Namespace) -> None:
    """Per axis: the whole record's min–max envelope, and a zoomed window."""
    dim = p.shape[1]
    labels = ("x", "y", "z") if dim == 3 else ("x",)
    end = target.start + target.duration
    w0 = min(max(args.start, target.start), max(end - args.window, target.start))
    zoom = (t >= w0) & (t <= w0 + args.window)
    for d in range(dim):
        ax = fig.add_subplot(grid[d, 0])
        tb, lo, hi = _envelope(t, p[:, d], rate)
        ax.fill_between(tb, lo, hi, color="0.6", lw=0)
        ax.set_ylabel(f"{labels[d]} [mm]")
        ax.set_xlim(target.start, end)
        if d == 0:
            ax.set_title("position over the whole record (min–max over 1.2 s)")
        if d == dim - 1:
            ax.set_xlabel("time [s]")
        ax.axvspan(w0, w0 + args.window, color="tab:orange", alpha=0.15, lw=0)
        axz = fig.add_subplot(grid[d, 1])
        axz.plot(t[zoom], p[zoom, d], lw=0.9, color="tab:blue")
        axz.set_xlim(w0, w0 + args.window)
        if d == 0:
            axz.set_title(f"{args.window:g} s window")
        if d == dim - 1:
            axz.set_xlabel("time [s]")


def _plot_rate_and_stats(fig, rate_cell, text_cell, target: _Target, t: np.ndarray, phase,
                         stats, dim: int) -> None:
    """The heart rate over time (synthetic motion only) and the statistics as text."""
    ax_hr = fig.add_subplot(rate_cell)
    if phase is not None:
        ax_hr.plot(t, 60 * phase.rate(t), color="tab:red", lw=1.0)
        ax_hr.set_xlim(target.start, target.start + target.duration)
        ax_hr.set_ylabel("heart rate\n[beats/min]")
        ax_hr.set_xlabel("time [s]")
    else:
        ax_hr.axis("off")
        ax_hr.text(0.0, 0.5, "heart rate unknown for a recording", transform=ax_hr.transAxes)
    ax_txt = fig.add_subplot(text_cell)
    ax_txt.axis("off")
    ax_txt.text(0.0, 1.0, "\n".join([
        f"peak-to-peak  {stats.peak_to_peak * 1e3:.2f} mm (largest axis range)",
        f"RMS           {stats.rms * 1e3:.2f} mm (about the mean"
        + (", 3-D)" if dim > 1 else ")"),
        "spectral peaks " + ", ".join(f"{v:.2f}" for v in stats.peaks[:6]) + " Hz",
    ]), transform=ax_txt.transAxes, va="top", family="monospace", fontsize=8)


def _plot_psd(ax, f: np.ndarray, s: np.ndarray, rate: float, stats) -> None:
    """The Welch PSD per axis, the spectral peaks marked."""
    dim = s.shape[1]
    labels = ("x", "y", "z") if dim == 3 else ("x",)
    for d in range(dim):
        ax.semilogy(f, s[:, d], lw=0.9, label=labels[d])
    ax.set_xlim(0, min(30.0, rate / 2))
    ax.set_ylim(max(np.max(s) * 1e-9, 1e-12), np.max(s) * 5)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD [mm²/Hz]")
    ax.set_title("power spectral density (Welch)")
    ax.legend(loc="upper right", ncols=dim)
    for fp in stats.peaks[:6]:
        ax.axvline(fp, color="0.5", lw=0.5, ls=":")


def _envelope(t: np.ndarray, y: np.ndarray, rate: float, window: float = 1.2,
              points: int = 3000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rolling min/max of ``y`` over ``window`` seconds (about one beat), decimated to
    ``points`` samples, so a long record plots as a clean band around the breathing."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    filled = np.where(np.isfinite(y), y, np.nanmean(y))
    size = max(1, round(window * rate))
    lo = minimum_filter1d(filled, size, mode="nearest")
    hi = maximum_filter1d(filled, size, mode="nearest")
    step = max(1, t.size // points)
    return t[::step], lo[::step], hi[::step]
