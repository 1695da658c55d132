"""Arrhythmia: a real annotated rhythm drives the heart phase; premature beats change the stroke.

The ``arrhythmia-apb`` scenario (:mod:`rhmpc.sim.heart.scenarios`) takes its beat times from the
MIT-BIH record 100 annotations shipped with the package (``sim/heart/physionet``), so the RR
intervals — the premature beats' short coupling intervals and the pauses after them — are real.
The beat morphology is the replica's, with the stroke of each premature beat and of the beat
after it changed (:func:`premature_stroke`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc.sim.heart.rr import RECORDS_DIR, beats_from_annotations

#: The real data the scenarios name their records in: the PhysioNet annotations shipped with
#: the package (:data:`rhmpc.sim.heart.rr.RECORDS_DIR`).
SHARED_DATA: Path = RECORDS_DIR

#: Premature beats: stroke gain = (coupling interval / median RR)^PREMATURE_STROKE_EXPONENT
#: (a shortened filling time gives a smaller stroke, Frank–Starling; exponent 1 assumed), and
#: the beat after the pause ×POST_PAUSE_POTENTIATION (post-extrasystolic potentiation;
#: 1.15 assumed, of the order reported for the beat after a premature beat, Cooper 1993,
#: Circulation 88:2962).
PREMATURE_STROKE_EXPONENT = 1.0
POST_PAUSE_POTENTIATION = 1.15


def record_beats(path: Path, start: float, duration: float,
                 name: str) -> tuple[np.ndarray, np.ndarray]:
    """Beat times [s] of record ``path`` in [start − 10 s, start + duration + 10 s], shifted so
    that ``start`` is t = 0, and their premature mask; ``name`` is the scenario (messages)."""
    if not path.with_suffix(".atr").is_file():
        raise ValueError(f"scenario {name} needs the PhysioNet annotations "
                         f"{path.with_suffix('.atr')} (missing from this install)")
    times, premature = beats_from_annotations(path)
    keep = (times >= start - 10.0) & (times <= start + duration + 10.0)
    return times[keep] - start, premature[keep]


def premature_stroke(times: np.ndarray, premature: np.ndarray) -> np.ndarray:
    """Per-beat stroke gain of an annotated rhythm [-], one per beat time.

    A premature beat i gets (RR_{i−1}/median RR)^PREMATURE_STROKE_EXPONENT (its shortened
    filling time), the beat after it POST_PAUSE_POTENTIATION, every other beat 1.
    """
    gain = np.ones(times.size)
    rr = np.diff(times)
    median = float(np.median(rr))
    for i in np.flatnonzero(premature):
        if i > 0:
            gain[i] = min(1.0, rr[i - 1] / median) ** PREMATURE_STROKE_EXPONENT
        if i + 1 < gain.size and not premature[i + 1]:
            gain[i + 1] = POST_PAUSE_POTENTIATION
    return gain
