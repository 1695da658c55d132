"""What ``rhmpc data`` works on: a named scenario (with its overrides) or a recording, and the
memory and time the work on it takes, checked before it starts.

A scenario's motion is synthesised in memory, so a duration (or a rate) whose work would not
fit in the memory available is refused before any work, with the memory and time it would
take; work longer than :data:`ANNOUNCE_AFTER` says how long it will take before it starts.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.errors import UsageError
from rhmpc.motion.text import fmt, size_bytes, time_span
from rhmpc.sim.heart import SCENARIOS, SPECS, make_scenario
from rhmpc.sim.heart.motion import MotionSource
from rhmpc.sim.heart.scenarios import DEFAULT_SEED
from rhmpc.sim.recordings import is_bag, load_recording

__all__ = ["ANNOUNCE_AFTER", "BPM_RANGE", "PLOT_RATE", "Request", "Target", "check_work",
           "export", "resolve", "seed_of", "work"]

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
@dataclass(frozen=True)
class Target:
    """What ``rhmpc data`` works on: a motion source with its natural rate and duration."""

    name: str
    source: MotionSource
    rate: float
    duration: float
    description: str
    start: float = 0.0



@dataclass(frozen=True)
class Request:
    """What an action of ``rhmpc data`` asks of a motion (the command line's options).

    Attributes
    ----------
    action : str
        ``list``, ``show``, ``export`` or ``plot``.
    duration : float or None
        Seconds to use [s] (default: the scenario's, or the whole recording).
    seed : int or None
        Seed of a scenario's beat-to-beat variability.
    bpm : float or None
        A scenario's constant heart rate [beats/min].
    record : str or None
        A PhysioNet record whose beats drive a scenario's heart.
    rate : float or None
        The rate to write or read at [Hz] (export's; a .mat file's without sample times).
    units, var, rows, cols, topic, frame, poi
        How to read a recording (``load_recording``'s keywords; ``poi``: which of several
        tracked points, from 1).
    """

    action: str
    duration: float | None = None
    seed: int | None = None
    bpm: float | None = None
    record: str | None = None
    rate: float | None = None
    units: str | None = None
    var: str | None = None
    rows: tuple[int, ...] | None = None
    cols: tuple[int, ...] | None = None
    topic: str | None = None
    frame: str | None = None
    poi: int | None = None

    @classmethod
    def of(cls, options) -> Request:
        """The request of an object with these attributes (an ``argparse.Namespace``)."""
        return cls(**{f.name: getattr(options, f.name, None) for f in fields(cls)})


def resolve(name: str, req: Request) -> Target:
    """Resolve NAME to a scenario (with the command-line overrides) or a recording."""
    _check_options(req)
    if name in SPECS:
        spec = SPECS[name]
        duration = spec.duration if req.duration is None else req.duration
        check_work(req.action, name, duration, _work_rate(req, spec.sensor_rate, True))
        sc = make_scenario(name, np.random.default_rng(seed_of(req)), **_overrides(req))
        return Target(sc.name, sc.source, sc.sensor_rate, sc.duration, sc.description)
    path = Path(name)
    if path.suffix.lower() in {".csv", ".npz", ".txt", ".mat"} or path.exists() or is_bag(path):
        if req.bpm is not None or req.record is not None:
            raise UsageError("--bpm and --record apply to scenarios, not recordings")
        rec = load_recording(path, **_read_options(req, path))
        duration = rec.duration if req.duration is None else min(req.duration, rec.duration)
        check_work(req.action, path.name, duration, _work_rate(req, rec.sample_rate, False))
        return Target(path.name, rec, rec.sample_rate, duration, f"recording {path}",
                       float(rec.t[0]))
    raise UsageError(f"unknown scenario {name!r}; valid names: {', '.join(SCENARIOS)} "
                     "(or the path of a .csv/.npz/.mat recording or a ROS bag)")


def _check_options(req: Request) -> None:
    """Refuse a --bpm, --duration or --rate outside its range (one line)."""
    if req.bpm is not None and not BPM_RANGE[0] <= req.bpm <= BPM_RANGE[1]:
        raise UsageError(f"--bpm must be within {BPM_RANGE[0]:g}–{BPM_RANGE[1]:g} beats/min, "
                         f"got {req.bpm:g}")
    if req.duration is not None and not (math.isfinite(req.duration) and req.duration > 0):
        raise UsageError(f"--duration must be positive, got {req.duration:g}")
    rate = getattr(req, "rate", None)
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise UsageError(f"--rate must be positive, got {rate:g}")


def seed_of(req: Request) -> int:
    """The seed of the beat-to-beat variability: ``seed``, or the scenarios' default."""
    return DEFAULT_SEED if req.seed is None else req.seed


def _overrides(req: Request) -> dict:
    """``make_scenario`` keywords from --bpm, --record and --duration."""
    overrides: dict = {}
    if req.bpm is not None:
        overrides["heart_rate"] = req.bpm / 60.0
    if req.record is not None:
        overrides["record"] = req.record
    if req.duration is not None:
        overrides["duration"] = req.duration
    return overrides


def _work_rate(req: Request, rate: float, synthetic: bool) -> float:
    """The rate [Hz] an action samples a source of natural ``rate`` at: export's --rate, the
    drawing rate of a synthetic motion's plot."""
    if req.action == "export" and req.rate is not None:
        return req.rate
    if req.action == "plot" and synthetic:
        return max(rate, PLOT_RATE)
    return rate


def work(action: str, duration: float, rate: float) -> tuple[float, float]:
    """(memory [B], time [s]) that ``action`` takes on ``duration`` seconds at ``rate``."""
    samples = duration * rate
    memory = BYTES_PER_SAMPLE * samples + BYTES_PER_SECOND * duration
    if action == "export":
        return memory, EXPORT_SECONDS_PER_SAMPLE * samples
    if action == "plot":
        return memory, PLOT_SECONDS_PER_SAMPLE * samples
    return memory, STATS_SECONDS_PER_SECOND * duration


def check_work(action: str, name: str, duration: float, rate: float) -> None:
    """Refuse work that would not fit in memory, saying how much it would take; announce work
    longer than :data:`ANNOUNCE_AFTER` on stderr."""
    memory, seconds = work(action, duration, rate)
    available = io.limits.available_memory()
    if memory > available:
        per_second = work(action, 1.0, rate)[0]
        raise UsageError(
            f"{fmt(duration)} s of {name} at {fmt(rate)} Hz is {duration * rate:.3g} "
            f"samples: {action} would need about {size_bytes(memory)} of memory and "
            f"{time_span(seconds)}; {size_bytes(available)} is available, enough for about "
            f"{available / per_second:.3g} s at this rate (lower --duration or --rate)")
    if seconds > ANNOUNCE_AFTER:
        print(f"rhmpc data: {action} of {fmt(duration)} s of {name} at {fmt(rate)} Hz "
              f"takes about {time_span(seconds)}", file=sys.stderr)


def _read_options(req: Request, path: Path) -> dict:
    """``load_recording`` keywords: --units, --topic, --frame, --poi always, --var/--rows/
    --cols/--rate for .mat."""
    out = {"units": req.units} if getattr(req, "units", None) else {}
    out |= {k: v for k, v in (("topic", req.topic), ("frame", req.frame), ("point", req.poi))
            if v is not None}  # the reader refuses those the file's format does not take
    if path.suffix.lower() == ".mat":
        for key in ("var", "rows", "cols", "rate"):
            if getattr(req, key, None) is not None:
                out[key] = getattr(req, key)
    elif any(getattr(req, k, None) is not None for k in ("var", "rows", "cols")):
        raise UsageError("--var, --rows and --cols apply to .mat files")
    return out


def export(target: Target, out: Path, rate: float | None, sensor: str | None,
           seed: int | None) -> int:
    """Write ``target``'s motion to ``out`` (.csv in s and mm, .npz in s and m) at ``rate``
    [Hz] (default its own), or with ``sensor`` that sensor's samples of it; returns the
    samples written."""
    from rhmpc.sim.recordings import export_source, save_recording
    from rhmpc.sim.sensors import sensor_from_name

    comment = f"rhmpc {target.name}: {target.description}"
    if sensor:
        instrument = sensor_from_name(sensor, rate=rate, dim=int(target.source.dim))
        seed = DEFAULT_SEED if seed is None else seed
        stream = instrument.measure(target.source, target.duration,
                                    np.random.default_rng(seed), t0=target.start)
        save_recording(out, stream.t, stream.z, comment + f"; measured by {instrument.name}")
        return len(stream)
    rate = target.rate if rate is None else rate
    export_source(target.source, out, target.duration, rate, target.start, comment)
    return max(1, round(target.duration * rate))
