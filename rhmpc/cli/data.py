"""`rhmpc data`: list, show, export and plot heart-motion scenarios and recordings.

``rhmpc data list``                 the named scenarios: what each replicates, its targets
``rhmpc data list --measure``       … and their statistics measured on the synthetic motion
``rhmpc data show NAME``            p-p, RMS, heart-rate range, spectral peaks, predictability
``rhmpc data export NAME FILE``     write the motion (or a sensor's samples) to .csv/.npz
``rhmpc data plot NAME FILE.png``   position per axis over time, heart rate and PSD

NAME is a scenario name or the path of a recording (.csv/.npz/.mat; for .mat: ``--var``,
``--rows``/``--cols``, ``--rate``, ``--units``; a ROS bag: ``--topic``, ``--frame``, whose
``show`` without ``--topic`` lists its topics). Millimetres appear only here.

A scenario's motion is synthesised in memory, so a ``--duration`` (or ``--rate``) whose work
would not fit in the memory available is refused before any work, with the memory and time it
would take; long work that fits says how long it will take before it starts.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.cli import COMMANDS
from rhmpc.cli.data_figure import heart_rate, motion_figure
from rhmpc.cli.text import fmt, mm, size_bytes, time_span
from rhmpc.errors import UsageError, one_line_warnings
from rhmpc.sim.heart import DEFAULT_SCENARIO, SCENARIOS, SPECS, make_scenario
from rhmpc.sim.heart.analysis import (
    motion_stats,
    predictability,
)
from rhmpc.sim.heart.invivo import source_statistics, statistics_table
from rhmpc.sim.heart.motion import MotionSource
from rhmpc.sim.heart.scenarios import DEFAULT_SEED, missing_data
from rhmpc.sim.heart.specs import ScenarioSpec
from rhmpc.sim.recordings import (
    RecordedMotion,
    coverage,
    coverage_lines,
    export_source,
    is_bag,
    load_recording,
    parse_indices,
    save_recording,
    survey,
    survey_lines,
)
from rhmpc.sim.sensors import SENSORS, sensor_from_name

#: The heart rates --bpm accepts [beats/min]: from deep bradycardia to a fast tachycardia.
BPM_RANGE = (20.0, 250.0)
#: Memory a scenario takes per sample synthesised [B] (positions and their temporaries,
#: measured at 430–490 B) and per second of motion [B] (its phase and variability tracks).
BYTES_PER_SAMPLE = 500.0
BYTES_PER_SECOND = 30e3
#: Work per sample [s]: written to a CSV file (export), drawn (plot); and per second of motion
#: for the statistics of ``show`` and ``list --measure`` (the 25-Hz predictability loop).
EXPORT_SECONDS_PER_SAMPLE = 15e-6
PLOT_SECONDS_PER_SAMPLE = 15e-6
STATS_SECONDS_PER_SECOND = 5e-3
#: Work longer than this is announced on stderr before it starts [s].
ANNOUNCE_AFTER = 10.0
#: The rate a synthetic motion is drawn at, at least, so that slow sensors show its shape [Hz].
PLOT_RATE = 250.0
#: The width of the tables' text [characters].
TABLE_WIDTH = 100


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
        "data", help=COMMANDS["data"],
        description="Heart-motion scenarios (synthetic replicas of the papers' data sets) "
        "and recordings: statistics, export and figures.")
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--seed", type=int, default=None,
                        help=f"seed of the beat-to-beat variability (default {DEFAULT_SEED})")
    common.add_argument("--duration", type=float, help="seconds to use (default: the scenario's)")
    common.add_argument("--bpm", type=float, help="constant heart rate [beats/min] "
                        f"({BPM_RANGE[0]:g}–{BPM_RANGE[1]:g})")
    common.add_argument("--record", help="PhysioNet record whose annotated beats drive the "
                        "heart: a shipped name (mitdb-100, 1003) or a path without extension")
    common.add_argument("--var", help="MATLAB variable holding the positions (.mat files)")
    common.add_argument("--rows", type=parse_indices, help="0-based rows holding x,y,z (.mat)")
    common.add_argument("--cols", type=parse_indices, help="0-based columns holding x,y,z (.mat)")
    common.add_argument("--units", choices=("mm", "m", "um", "cm"),
                        help="length unit when the file does not state it (a CSV file's "
                        "default is mm; an NPZ or MAT file needs it)")
    common.add_argument("--topic", help="a ROS bag's topic to read (show lists them)")
    common.add_argument("--frame", help="the child frame read from a ROS bag's tf topic")
    common.add_argument("--poi", type=int, help="which of several tracked points is read, from 1")

    p_list = actions.add_parser(
        "list", parents=[common], help="the scenarios: what they replicate, their targets",
        description="The named scenarios and their calibration targets, at once. --measure "
        "(implied by --duration, --seed, --bpm and --record) also synthesises each one and "
        "measures its statistics (several seconds).")
    p_list.add_argument("--measure", action="store_true",
                        help="also measure each scenario's statistics on its motion")
    p_list.add_argument("--json", action="store_true", help="machine-readable output")

    p_show = actions.add_parser("show", parents=[common], help="statistics of one scenario/file")
    p_show.add_argument("name", nargs="?", default=DEFAULT_SCENARIO,
                        help=f"scenario or recording file (default {DEFAULT_SCENARIO})")
    p_show.add_argument("--json", action="store_true", help="machine-readable output")
    p_show.add_argument("--rate", type=float, help="sample rate of a .mat file without sample "
                        "times [Hz]")

    p_exp = actions.add_parser("export", parents=[common], help="write a scenario to .csv/.npz")
    p_exp.add_argument("name", help="scenario or recording file")
    p_exp.add_argument("file", help="output .csv (s, mm) or .npz (s, m)")
    p_exp.add_argument("--rate", type=float, help="sample rate [Hz] (default: the sensor's; for "
                       "a .mat file without sample times also its rate)")
    p_exp.add_argument("--sensor", choices=SENSORS,
                       help="write this sensor's noisy samples instead of the true motion")
    p_exp.add_argument("--force", action="store_true", help="overwrite an existing file")

    p_plot = actions.add_parser("plot", parents=[common], help="figure: position and PSD")
    p_plot.add_argument("name", help="scenario or recording file")
    p_plot.add_argument("file", help="output image (.png, .pdf, .svg)")
    p_plot.add_argument("--rate", type=float, help="sample rate of a .mat file without sample "
                        "times [Hz]")
    p_plot.add_argument("--window", type=float, default=10.0,
                        help="length of the zoomed time window of a long record [s] (default "
                        "%(default)s; a record up to twice as long is drawn whole)")
    p_plot.add_argument("--start", type=float, default=0.0,
                        help="start of the zoomed window [s] (default %(default)s)")
    parser.set_defaults(func=run, action=None)


def run(args: argparse.Namespace) -> int:
    """Dispatch to the action; a recording's warnings (``RecordingWarning``) are printed one
    line each."""
    if args.action is None:
        raise UsageError("choose an action: list, show, export or plot")
    action = {"list": _list, "show": _show, "export": _export, "plot": _plot}[args.action]
    with one_line_warnings("rhmpc data"):
        return action(args)


def _target(name: str, args: argparse.Namespace) -> _Target:
    """Resolve NAME to a scenario (with the command-line overrides) or a recording."""
    _check_options(args)
    if name in SPECS:
        spec = SPECS[name]
        duration = spec.duration if args.duration is None else args.duration
        _check_work(args.action, name, duration, _work_rate(args, spec.sensor_rate, True))
        sc = make_scenario(name, np.random.default_rng(_seed(args)), **_overrides(args))
        return _Target(sc.name, sc.source, sc.sensor_rate, sc.duration, sc.description)
    path = Path(name)
    if path.suffix.lower() in {".csv", ".npz", ".txt", ".mat"} or path.exists() or is_bag(path):
        if args.bpm is not None or args.record is not None:
            raise UsageError("--bpm and --record apply to scenarios, not recordings")
        rec = load_recording(path, **_read_options(args, path))
        duration = rec.duration if args.duration is None else min(args.duration, rec.duration)
        _check_work(args.action, path.name, duration, _work_rate(args, rec.sample_rate, False))
        return _Target(path.name, rec, rec.sample_rate, duration, f"recording {path}",
                       float(rec.t[0]))
    raise UsageError(f"unknown scenario {name!r}; valid names: {', '.join(SCENARIOS)} "
                     "(or the path of a .csv/.npz/.mat recording or a ROS bag)")


def _check_options(args: argparse.Namespace) -> None:
    """Refuse a --bpm, --duration or --rate outside its range (one line)."""
    if args.bpm is not None and not BPM_RANGE[0] <= args.bpm <= BPM_RANGE[1]:
        raise UsageError(f"--bpm must be within {BPM_RANGE[0]:g}–{BPM_RANGE[1]:g} beats/min, "
                         f"got {args.bpm:g}")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration must be positive, got {args.duration:g}")
    rate = getattr(args, "rate", None)
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise UsageError(f"--rate must be positive, got {rate:g}")


def _seed(args: argparse.Namespace) -> int:
    return DEFAULT_SEED if args.seed is None else args.seed


def _overrides(args: argparse.Namespace) -> dict:
    """``make_scenario`` keywords from --bpm, --record and --duration."""
    overrides: dict = {}
    if args.bpm is not None:
        overrides["heart_rate"] = args.bpm / 60.0
    if args.record is not None:
        overrides["record"] = args.record
    if args.duration is not None:
        overrides["duration"] = args.duration
    return overrides


def _work_rate(args: argparse.Namespace, rate: float, synthetic: bool) -> float:
    """The rate [Hz] an action samples a source of natural ``rate`` at: export's --rate, the
    drawing rate of a synthetic motion's plot."""
    if args.action == "export" and args.rate is not None:
        return args.rate
    if args.action == "plot" and synthetic:
        return max(rate, PLOT_RATE)
    return rate


def _work(action: str, duration: float, rate: float) -> tuple[float, float]:
    """(memory [B], time [s]) that ``action`` takes on ``duration`` seconds at ``rate``."""
    samples = duration * rate
    memory = BYTES_PER_SAMPLE * samples + BYTES_PER_SECOND * duration
    if action == "export":
        return memory, EXPORT_SECONDS_PER_SAMPLE * samples
    if action == "plot":
        return memory, PLOT_SECONDS_PER_SAMPLE * samples
    return memory, STATS_SECONDS_PER_SECOND * duration


def _check_work(action: str, name: str, duration: float, rate: float) -> None:
    """Refuse work that would not fit in memory, saying how much it would take; announce work
    longer than :data:`ANNOUNCE_AFTER` on stderr."""
    memory, seconds = _work(action, duration, rate)
    available = io.limits.available_memory()
    if memory > available:
        per_second = _work(action, 1.0, rate)[0]
        raise UsageError(
            f"{fmt(duration)} s of {name} at {fmt(rate)} Hz is {duration * rate:.3g} "
            f"samples: {action} would need about {size_bytes(memory)} of memory and "
            f"{time_span(seconds)}; {size_bytes(available)} is available, enough for about "
            f"{available / per_second:.3g} s at this rate (lower --duration or --rate)")
    if seconds > ANNOUNCE_AFTER:
        print(f"rhmpc data: {action} of {fmt(duration)} s of {name} at {fmt(rate)} Hz "
              f"takes about {time_span(seconds)}", file=sys.stderr)


def _read_options(args: argparse.Namespace, path: Path) -> dict:
    """``load_recording`` keywords: --units, --topic, --frame, --poi always, --var/--rows/
    --cols/--rate for .mat."""
    out = {"units": args.units} if getattr(args, "units", None) else {}
    out |= {k: v for k, v in (("topic", args.topic), ("frame", args.frame), ("point", args.poi))
            if v is not None}  # the reader refuses those the file's format does not take
    if path.suffix.lower() == ".mat":
        for key in ("var", "rows", "cols", "rate"):
            if getattr(args, key, None) is not None:
                out[key] = getattr(args, key)
    elif any(getattr(args, k, None) is not None for k in ("var", "rows", "cols")):
        raise UsageError("--var, --rows and --cols apply to .mat files")
    return out


def _stats_row(target: _Target) -> dict:
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


def _list(args: argparse.Namespace) -> int:
    """The scenarios' specifications, or (``--measure``) their measured statistics."""
    measure = args.measure or any(getattr(args, k) is not None
                                  for k in ("duration", "seed", "bpm", "record"))
    if any(getattr(args, k) is not None for k in ("var", "rows", "cols", "units", "topic",
                                                  "frame", "poi")):
        raise UsageError("--var, --rows, --cols, --units, --topic, --frame and --poi apply to "
                         "recordings, not to list")
    names = []
    for name in SCENARIOS:
        if (missing := missing_data(name)) is not None:
            print(f"# {name}: skipped, needs {missing}", file=sys.stderr)
            continue
        names.append(name)
    rows = _measured_rows(names, args) if measure else [_spec_row(SPECS[n]) for n in names]
    if args.json:
        print(json.dumps(rows, indent=2))
    elif measure:
        print("\n".join(_measured_table(rows)))
    else:
        print("\n".join(_spec_table(rows)))
    return 0


def _spec_row(spec: ScenarioSpec) -> dict:
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


def _spec_table(rows: list[dict]) -> list[str]:
    """The table of :func:`_spec_row` rows, each with its description below."""
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


def _measured_rows(names: list[str], args: argparse.Namespace) -> list[dict]:
    """Each scenario's measured statistics beside its targets, with progress on stderr."""
    from tqdm import tqdm

    rows = []
    with tqdm(names, desc="measuring", unit="scenario", leave=False, file=sys.stderr,
              mininterval=0.5) as bar:
        for name in bar:
            bar.set_postfix_str(name)
            row = _stats_row(_target(name, args))
            spec = SPECS[name]
            row["target_peak_to_peak_mm"] = round(spec.peak_to_peak * 1e3, 3)
            row["target_rms_mm"] = None if spec.rms is None else round(spec.rms * 1e3, 3)
            rows.append(row)
    return rows


def _measured_table(rows: list[dict]) -> list[str]:
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


def _show(args: argparse.Namespace) -> int:
    bag = survey(args.name) if is_bag(args.name) else None  # its topics, then one's motion
    if bag is not None and args.topic is None:
        print(json.dumps(bag, indent=2) if args.json else "\n".join(survey_lines(bag)))
        return 0
    target = _target(args.name, args)
    row = _stats_row(target) | ({"bag": bag} if bag else {})
    invivo = args.name in SPECS and SPECS[args.name].heart == "invivo"
    if invivo:  # the in-vivo regime beside the recording it was built from
        row["regime"] = source_statistics(target.source, target.duration)
    if args.json:
        print(json.dumps(row, indent=2))
        return 0
    print("\n".join([*(survey_lines(bag) if bag else []), *_show_lines(row)]))
    if invivo:
        print("  the in-vivo recording's statistics (rhmpc.sim.heart.invivo, sampled at 25 Hz):")
        print("\n".join(statistics_table(row["regime"])))
    return 0


def _show_lines(row: dict) -> list[str]:
    """``data show``'s lines for a :func:`_stats_row` row."""
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


def _export(args: argparse.Namespace) -> int:
    out = Path(args.file)
    if out.suffix.lower() not in {".csv", ".npz"}:
        raise UsageError(f"{out}: output must end in .csv or .npz")
    if out.exists() and not args.force:
        raise UsageError(f"{out} exists; pass --force to overwrite")
    io.check_output(out, inputs=[args.name])
    target = _target(args.name, args)
    rate = target.rate if args.rate is None else args.rate
    comment = f"rhmpc {target.name}: {target.description}"
    if args.sensor:
        sensor = sensor_from_name(args.sensor, rate=args.rate, dim=int(target.source.dim))
        stream = sensor.measure(target.source, target.duration, np.random.default_rng(_seed(args)),
                                t0=target.start)
        save_recording(out, stream.t, stream.z, comment + f"; measured by {sensor.name}")
        n = len(stream)
    else:
        export_source(target.source, out, target.duration, rate, target.start, comment)
        n = max(1, round(target.duration * rate))
    print(f"wrote {n} samples of {target.name} to {out}")
    return 0


def _plot(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not (math.isfinite(args.window) and args.window > 0):
        raise UsageError(f"--window must be positive, got {args.window:g}")
    if not math.isfinite(args.start):
        raise UsageError(f"--start must be a number of seconds, got {args.start:g}")
    target = _target(args.name, args)
    phase = getattr(target.source, "phase", None)
    rate = max(target.rate, PLOT_RATE) if phase is not None else target.rate
    n = round(target.duration * rate) + 1
    t = target.start + np.arange(n) / rate
    p = np.asarray(target.source.position(t)).reshape(n, -1) * 1e3
    with np.errstate(over="ignore", invalid="ignore"):
        stats = motion_stats(target.source, target.duration, target.rate, target.start)
    heart = heart_rate(t, p, rate, phase)
    fig = motion_figure(plt, target, t, p, rate, heart, stats, args)
    out = Path(args.file)
    try:
        io.save_figure(fig, out, dpi=110)
    except io.FileError:
        raise
    except (OSError, ValueError) as exc:
        raise UsageError(f"{out}: cannot write the figure ({exc})") from None
    finally:
        plt.close(fig)
    print(f"wrote {out}")
    return 0
