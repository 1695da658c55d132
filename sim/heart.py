"""Heart-motion sources: synthetic scenarios, recorded files and RR-interval driving.

This is the public entry point; the work is split over small modules:

* :mod:`sim.rr` — heart phase φ(t): heart-rate profiles, RR intervals from PhysioNet
  annotations, the synthetic RR generator;
* :mod:`sim.motion` — the quasi-periodic motion model
  p(t) = p₀ + b(t) + (1 + κ cos(2π f_r t + ψ))·g(φ)⊙h(φ(t));
* :mod:`sim.variability` — the physiological variability (HRV with RSA, beat-to-beat stroke and
  timing, breath period and depth, drift, breathing–heartbeat coupling), seeded, switchable;
* :mod:`sim.arrhythmia` — an annotated real rhythm with premature-beat strokes (arrhythmia-apb);
* :mod:`sim.scenarios` — the named replicas of the papers' data sets and their calibration;
* :mod:`sim.recordings` — CSV/NPZ recordings users bring, and export;
* :mod:`sim.analysis` — peak-to-peak, RMS, spectra.

Every source has ``dim`` and ``position(t)`` → metres, shape ``(dim,)`` for a float ``t`` and
``(n, dim)`` for an array of ``n`` times; NaN marks missing data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sim.analysis import MotionStats, motion_stats
from sim.motion import MotionSource, SyntheticHeartMotion
from sim.recordings import (
    RecordedMotion,
    RecordingError,
    export_source,
    load_recording,
    save_recording,
)
from sim.rr import (
    BEAT_SYMBOLS,
    PhaseTrack,
    RRSettings,
    StaircaseProfile,
    beat_times_from_annotations,
    beat_times_from_rr,
    rr_from_annotations,
    synthetic_rr,
)
from sim.scenarios import (
    DEFAULT_SCENARIO,
    SCENARIOS,
    SPECS,
    Scenario,
    ScenarioSpec,
    make_scenario,
)
from sim.variability import VariabilitySettings

__all__ = [
    "BEAT_SYMBOLS",
    "DEFAULT_SCENARIO",
    "SCENARIOS",
    "SPECS",
    "MotionSource",
    "MotionStats",
    "PhaseTrack",
    "RRSettings",
    "RecordedMotion",
    "RecordingError",
    "Scenario",
    "ScenarioSpec",
    "StaircaseProfile",
    "SyntheticHeartMotion",
    "VariabilitySettings",
    "beat_times_from_annotations",
    "beat_times_from_rr",
    "export_scenario",
    "load_recording",
    "make_scenario",
    "motion_stats",
    "rr_from_annotations",
    "save_recording",
    "synthetic_rr",
]


def export_scenario(scenario: Scenario | str, path: str | Path, duration: float | None = None,
                    rate: float | None = None, rng: np.random.Generator | None = None) -> Path:
    """Write a scenario's true motion to a CSV (s, mm) or NPZ (s, m) file.

    Parameters
    ----------
    scenario : Scenario or str
        A scenario, or a name for :func:`make_scenario` (with ``rng``).
    path : str or Path
        ``.csv`` or ``.npz``; :func:`load_recording` reads it back.
    duration : float, optional
        Seconds to write [s]; default the scenario's duration.
    rate : float, optional
        Sample rate [Hz]; default the scenario's sensor rate.
    rng : numpy.random.Generator, optional
        Passed to :func:`make_scenario` when ``scenario`` is a name.
    """
    sc = make_scenario(scenario, rng) if isinstance(scenario, str) else scenario
    duration = sc.duration if duration is None else float(duration)
    rate = sc.sensor_rate if rate is None else float(rate)
    comment = f"rhmpc scenario {sc.name}: {sc.description}; synthetic, not measured data"
    return export_source(sc.source, path, duration, rate, comment=comment)
