"""Injected faults of the instruments: a sensor that freezes, a stream that jumps, a burst of
missing samples, encoders that stick — each kind declared once, here.

Each kind is a frozen dataclass acting on the samples whose measurement time lies in its window
``start_s ≤ t < end_s`` (:meth:`corrupt`; ``apply(stream, rng)`` like every sensor stage,
:mod:`rhmpc.sim.sensors.stream`); the truth the sensor measures is never touched:

======================  ================================================================
:class:`SensorFreeze`   z_k = z_h for t_k in the window, h the last sample before it
                        (stamps advance, the value does not)
:class:`StreamJump`     z_k = z_k + o for t_k in the window (a persistent step by default)
:class:`NaNBurst`       z_k = NaN for t_k in the window (the samples are missing)
:class:`EncoderStick`   the joints' readings q̃_k = q̃_h for t_k in the window (on the stream
                        of encoder readings, one row a control tick)
======================  ================================================================

A kind declares its name (``kind``), its one-line form (``form``, ``KIND@START[:ARGUMENT…]``, the
start in seconds from the start of the run, and ``arguments``, read in order), what it does
(``what``) and the stream it acts on (``target``: the sensor's ``"samples"`` or the
``"encoders"``). :data:`GRAMMAR`, :func:`parse_fault` (the command line's ``--fault`` and a
run's ``[faults]`` table, :class:`FaultSettings`), the loop (:mod:`rhmpc.sim.loop.faults`) and each
fault's record read the declaration; a new kind is a class here, added to :data:`FAULT_KINDS`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from rhmpc.sim.sensors.stream import SampleStream

__all__ = ["FAULT_KINDS", "GRAMMAR", "EncoderStick", "FaultSettings", "FaultySamples", "NaNBurst",
           "SensorFreeze", "StreamJump", "parse_fault"]

#: Length units a jump's offset may carry [m per unit].
LENGTH_UNITS: dict[str, float] = {"mm": 1e-3, "um": 1e-6, "m": 1.0}


def _window(start_s: float, duration_s: float, name: str) -> None:
    """Check a window: a finite start ≥ 0 [s] and a duration > 0 [s] (inf allowed)."""
    if not (_real(start_s) and math.isfinite(start_s) and start_s >= 0):
        raise ValueError(f"{name}: start_s must be a finite time >= 0 [s], got {start_s!r}")
    if not (_real(duration_s) and not math.isnan(duration_s) and duration_s > 0):
        raise ValueError(f"{name}: duration_s must be > 0 [s], got {duration_s!r}")


def _real(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def held_index(t: np.ndarray, start_s: float) -> int:
    """Index of the last sample measured before ``start_s`` (−1 if none)."""
    return int(np.searchsorted(t, start_s, side="left")) - 1


def _number(text: str, what: str, spec: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"fault {spec!r}: {what} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"fault {spec!r}: {what} must be finite, got {text!r}")
    return value


def _duration(text: str, spec: str) -> float:
    return _number(text, "the duration", spec)


def _offset(text: str, spec: str) -> tuple[float, float, float]:
    """``5mm`` (along x) or ``5,0,-2mm`` → metres."""
    m = _LENGTH.match(text.strip().lower())
    if m is None:
        raise ValueError(f"fault {spec!r}: the offset needs a length unit (mm, um or m), e.g. "
                         f"5mm or 5,0,-2mm, got {text!r}")
    values = [_number(v, "the offset", spec) for v in m["values"].split(",")]
    if len(values) not in (1, 3):
        raise ValueError(f"fault {spec!r}: the offset is one length (along x) or three (x,y,z)")
    scale = LENGTH_UNITS[m["unit"]]
    values = [*values, 0.0, 0.0] if len(values) == 1 else values
    return tuple(scale * v for v in values)


def _joints(text: str, spec: str) -> tuple[int, ...]:
    try:
        return tuple(int(j) for j in text.split(","))
    except ValueError:
        raise ValueError(f"fault {spec!r}: joints are 0-based integers separated by commas, "
                         f"got {text!r}") from None


_LENGTH = re.compile(r"^(?P<values>[0-9e+\-., ]+?)\s*(?P<unit>mm|um|m)$")


@dataclass(frozen=True)
class _Windowed:
    """A fault over the samples measured in ``start_s ≤ t < start_s + duration_s``."""

    #: its name in the one-line form
    kind: ClassVar[str] = ""
    #: its one-line form
    form: ClassVar[str] = ""
    #: what it does, for help texts
    what: ClassVar[str] = ""
    #: the stream it acts on: the sensor's "samples" or the "encoders"
    target: ClassVar[str] = "samples"
    #: the arguments after START, in order: (field, reader of its text)
    arguments: ClassVar[tuple[tuple[str, Callable[[str, str], object]], ...]] = ()
    #: how many of them the form requires
    required: ClassVar[int] = 1
    start_s: float
    duration_s: float

    def __post_init__(self) -> None:
        _window(self.start_s, self.duration_s, self.kind)

    @property
    def end_s(self) -> float:
        """End of the window [s] (inf for a persistent fault)."""
        return self.start_s + self.duration_s

    def inside(self, t: np.ndarray) -> np.ndarray:
        """Mask of the times ``t`` [s] inside the window."""
        t = np.asarray(t, dtype=float)
        return (t >= self.start_s) & (t < self.end_s)

    def corrupt(self, t: np.ndarray, z: np.ndarray, held: np.ndarray | None) -> np.ndarray:
        """``z`` (n, d) as the fault leaves it (a copy if it changes), ``held`` the sample
        measured last before the window (None if there is none)."""
        raise NotImplementedError

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        """The stream with the fault applied (stamps and arrivals unchanged); no random draw."""
        h = held_index(stream.t, self.start_s)
        held = stream.z[h] if h >= 0 else None
        return replace(stream, z=self.corrupt(stream.t, stream.z, held))


@dataclass(frozen=True)
class SensorFreeze(_Windowed):
    """The sensor repeats its last sample: z_k = z_h for start ≤ t_k < end, h the last sample
    measured before ``start_s`` (with none, the window's first), stamps advancing.

    Attributes
    ----------
    start_s : float
        When the sensor freezes [s].
    duration_s : float
        How long it stays frozen [s].
    """

    kind: ClassVar[str] = "freeze"
    form: ClassVar[str] = "freeze@START:DURATION"
    what: ClassVar[str] = "the sensor repeats its last sample"
    arguments: ClassVar = (("duration_s", _duration),)

    def corrupt(self, t, z, held):
        mask = self.inside(t)
        if not mask.any():
            return z
        z = np.array(z, dtype=float)
        z[mask] = z[np.argmax(mask)] if held is None else held
        return z


@dataclass(frozen=True)
class StreamJump(_Windowed):
    """A step of the measured stream: z_k = z_k + o for start ≤ t_k < end; the truth does not
    move (a sensor's calibration shift, a crystal that slipped).

    Attributes
    ----------
    start_s : float
        When the stream jumps [s].
    offset_m : tuple of float
        The step o (x, y, z) [m]; a 1-D stream (along x) takes its x component.
    duration_s : float
        How long the step lasts [s]; inf (default): to the end of the run.
    """

    kind: ClassVar[str] = "jump"
    form: ClassVar[str] = "jump@START:OFFSET[:DURATION]"
    what: ClassVar[str] = ("the stream steps by OFFSET, a length with its unit along x, 5mm, or "
                           "x,y,z, 5,0,-2mm; to the end of the run by default")
    arguments: ClassVar = (("offset_m", _offset), ("duration_s", _duration))
    offset_m: tuple[float, float, float] = (5e-3, 0.0, 0.0)
    duration_s: float = math.inf

    def __post_init__(self) -> None:
        super().__post_init__()
        o = self.offset_m
        if not (isinstance(o, tuple | list) and len(o) == 3
                and all(_real(v) and math.isfinite(v) for v in o)):
            raise ValueError(f"jump: offset_m must be 3 finite lengths [m], got {o!r}")
        object.__setattr__(self, "offset_m", tuple(float(v) for v in o))

    def corrupt(self, t, z, held):
        mask = self.inside(t)
        if not mask.any():
            return z
        z = np.array(z, dtype=float)
        z[mask] += np.asarray(self.offset_m)[: z.shape[1]]
        return z


@dataclass(frozen=True)
class NaNBurst(_Windowed):
    """A burst of missing samples: z_k = NaN for start ≤ t_k < end (an occlusion, a lost
    connection).

    Attributes
    ----------
    start_s : float
        When the burst begins [s].
    duration_s : float
        Its length [s] (0.5 s by default).
    """

    kind: ClassVar[str] = "nan"
    form: ClassVar[str] = "nan@START[:DURATION]"
    what: ClassVar[str] = "missing samples, 0.5 s by default"
    arguments: ClassVar = (("duration_s", _duration),)
    required: ClassVar[int] = 0
    duration_s: float = 0.5

    def corrupt(self, t, z, held):
        mask = self.inside(t)
        if not mask.any():
            return z
        z = np.array(z, dtype=float)
        z[mask] = np.nan
        return z


@dataclass(frozen=True)
class EncoderStick(_Windowed):
    """Encoders that stick: the readings of ``joints`` hold their last value before
    ``start_s`` (q̃_k = q̃_h) for start ≤ t_k < end while the arm moves on.

    Applied to the encoders' readings, one row a control tick (``t`` the tick's time [s], ``z``
    the joint angles [rad]); the loop reads them through
    :class:`rhmpc.sim.loop.faults.FaultyEncoders`.

    Attributes
    ----------
    start_s : float
        When the encoders stick [s].
    duration_s : float
        How long they stay stuck [s].
    joints : tuple of int or None
        The stuck joints (0-based); None: every joint.
    """

    kind: ClassVar[str] = "stick"
    form: ClassVar[str] = "stick@START:DURATION[:JOINTS]"
    what: ClassVar[str] = "encoder readings hold; 0-based joints, e.g. 0,2; every joint by default"
    target: ClassVar[str] = "encoders"
    arguments: ClassVar = (("duration_s", _duration), ("joints", _joints))
    joints: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.joints is not None:
            joints = tuple(self.joints)
            if not joints or any(isinstance(j, bool) or not isinstance(j, int) or j < 0
                                 for j in joints) or len(set(joints)) != len(joints):
                raise ValueError(f"stick: joints must be distinct integers >= 0, got "
                                 f"{self.joints!r}")
            object.__setattr__(self, "joints", joints)

    def columns(self, n: int) -> list[int]:
        """The stuck joints among ``n`` (``ValueError`` for one the arm does not have)."""
        if self.joints is None:
            return list(range(n))
        if max(self.joints) >= n:
            raise ValueError(f"stick: joint {max(self.joints)} does not exist (the arm has "
                             f"{n} joints, 0 … {n - 1})")
        return list(self.joints)

    def corrupt(self, t, z, held):
        mask = self.inside(t)
        if not mask.any():
            return z
        z = np.array(z, dtype=float)
        cols = self.columns(z.shape[1])
        source = z[np.argmax(mask)] if held is None else np.asarray(held, dtype=float)
        z[np.ix_(mask, cols)] = source[cols]
        return z


#: Every fault by the name of its one-line form.
FAULT_KINDS: dict[str, type[_Windowed]] = {c.kind: c for c in (SensorFreeze, StreamJump, NaNBurst,
                                                                EncoderStick)}
#: The one-line forms, for help texts and error messages.
GRAMMAR = "KIND@START[:ARG…] with START in s: " + ", ".join(
    f"{c.form} ({c.what})" for c in FAULT_KINDS.values())


def parse_fault(spec: str) -> _Windowed:
    """A fault from its one-line form (its kind's ``form`` and ``arguments``; :data:`GRAMMAR`).

    Raises
    ------
    ValueError
        A malformed form or a value out of range, in one line naming the form.
    """
    kind, at, rest = str(spec).strip().partition("@")
    cls = FAULT_KINDS.get(kind.lower())
    args = rest.split(":")
    if not at or cls is None or not 1 + cls.required <= len(args) <= 1 + len(cls.arguments) \
            or any(not a.strip() for a in args):
        raise ValueError(f"fault {spec!r}: expected {GRAMMAR}")
    start = _number(args[0], "the start", spec)
    values = {name: read(text, spec)
              for (name, read), text in zip(cls.arguments, args[1:], strict=False)}
    try:
        return cls(start, **values)
    except ValueError as exc:
        raise ValueError(f"fault {spec!r}: {str(exc).partition(': ')[2]}") from None


class FaultySamples:
    """A sample source (:class:`rhmpc.sim.sensors.stream.SampleSource`) with faults on its samples
    applied to each block, by their measurement time (the samples delivered to the control rate,
    and the raw ones a slow sensor's clock reads).

    Sample ``k`` is ``z_k`` after every fault in turn (``fault.corrupt``), the sample each one
    holds (the last measured before its window) read once, at construction, with the faults
    before it applied. Stamps and arrivals are the source's. A source with raw samples
    (``recorded``, read by a slow sensor's clock) gets them with the same faults.
    """

    def __init__(self, samples, faults) -> None:
        self.samples, self.faults = samples, tuple(faults)
        self.held: list[np.ndarray | None] = []
        for k, fault in enumerate(self.faults):
            self.held.append(self._before(fault.start_s, k))
        if hasattr(samples, "recorded"):
            self.recorded = FaultySamples(samples.recorded, self.faults)

    def _before(self, start_s: float, upto: int) -> np.ndarray | None:
        """The last sample measured before ``start_s``, the first ``upto`` faults applied."""
        j = self.samples.index_at(start_s)
        if j >= 0 and float(self.samples.block(j, j + 1)[0][0]) >= start_s:
            j -= 1
        if j < 0:
            return None
        t, z, _ = self.samples.block(j, j + 1)
        for fault, held in zip(self.faults[:upto], self.held, strict=False):
            z = fault.corrupt(t, z, held)
        return np.array(z[0], dtype=float)

    def __len__(self) -> int:
        return len(self.samples)

    def index_at(self, t: float) -> int:
        return self.samples.index_at(t)

    def block(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t, z, arrival = self.samples.block(a, b)
        for fault, held in zip(self.faults, self.held, strict=True):
            z = fault.corrupt(t, z, held)
        return t, z, arrival


@dataclass(frozen=True)
class FaultSettings:
    """The faults injected into a run (the ``[faults]`` table).

    Attributes
    ----------
    events : tuple of str
        Each fault in its one-line form (:func:`parse_fault`), e.g.
        ``("freeze@14:0.3", "jump@20:5mm")``; empty (default): no fault.
    after_s : float
        Length of the window after each fault over which the run's report measures the
        recovery [s].
    """

    events: tuple[str, ...] = ()
    after_s: float = 1.0

    def __post_init__(self) -> None:
        if isinstance(self.events, str) or not isinstance(self.events, tuple | list):
            raise ValueError(f"events must be a list of faults ({GRAMMAR}), got "
                             f"{self.events!r}")
        object.__setattr__(self, "events", tuple(str(e) for e in self.events))
        for spec in self.events:
            parse_fault(spec)
        if not (_real(self.after_s) and math.isfinite(self.after_s) and self.after_s > 0):
            raise ValueError(f"after_s must be a finite time > 0 [s], got {self.after_s!r}")

    @property
    def faults(self) -> tuple:
        """The parsed faults, in the order given."""
        return tuple(parse_fault(spec) for spec in self.events)

    def check(self, duration: float) -> None:
        """Every fault starts within a run of ``duration`` [s] and a finite one ends in it."""
        for spec, fault in zip(self.events, self.faults, strict=True):
            if fault.start_s >= duration:
                raise ValueError(f"fault {spec!r} starts at {fault.start_s:g} s, not within "
                                 f"the run's {duration:g} s")
            if math.isfinite(fault.end_s) and fault.end_s > duration + 1e-9:
                raise ValueError(f"fault {spec!r} ends at {fault.end_s:g} s, after the run's "
                                 f"{duration:g} s")
