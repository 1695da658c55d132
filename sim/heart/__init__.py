"""Heart motion: the quasi-periodic model, its variability, the named replicas, statistics.

==================  ==============================================================
``rr``              heart phase φ(t): heart-rate profiles, RR intervals from PhysioNet
                    annotations, the synthetic RR generator
``motion``          the quasi-periodic motion model
                    p(t) = p₀ + b(t) + (1 + κ cos(2π f_r t + ψ))·g(φ)⊙h(φ(t))
``variability``     physiological variability (HRV with RSA, beat-to-beat stroke and
                    timing, breath period and depth, drift, breathing–heartbeat coupling)
``arrhythmia``      an annotated real rhythm with premature-beat strokes
``invivo``          the in-vivo regime: breathing-dominated motion with beat-to-beat changes
                    of shape, amplitude and timing, built from a recording's statistics
``specs``           what the papers report for each replicated data set
``scenarios``       the named replicas of the papers' data sets and their calibration
``analysis``        peak-to-peak, RMS, spectra, predictability
==================  ==============================================================

Every source has ``dim`` and ``position(t)`` → metres, shape ``(dim,)`` for a float ``t`` and
``(n, dim)`` for an array of ``n`` times; NaN marks missing data.
"""

from rhmpc.sim.heart.analysis import MotionStats, motion_stats
from rhmpc.sim.heart.motion import MotionSource, SyntheticHeartMotion
from rhmpc.sim.heart.rr import (
    BEAT_SYMBOLS,
    PhaseTrack,
    RRSettings,
    StaircaseProfile,
    beat_times_from_annotations,
    beat_times_from_rr,
    rr_from_annotations,
    synthetic_rr,
)
from rhmpc.sim.heart.scenarios import (
    DEFAULT_SCENARIO,
    SCENARIOS,
    SPECS,
    Scenario,
    ScenarioSpec,
    make_scenario,
)
from rhmpc.sim.heart.variability import VariabilitySettings

__all__ = [
    "BEAT_SYMBOLS", "DEFAULT_SCENARIO", "SCENARIOS", "SPECS", "MotionSource", "MotionStats",
    "PhaseTrack", "RRSettings", "Scenario", "ScenarioSpec", "StaircaseProfile",
    "SyntheticHeartMotion", "VariabilitySettings", "beat_times_from_annotations",
    "beat_times_from_rr", "make_scenario", "motion_stats", "rr_from_annotations", "synthetic_rr",
]
