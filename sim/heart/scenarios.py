"""Named heart-motion scenarios: synthetic replicas of the papers' data sets.

The in-vivo recordings of Tuna et al. (T-RO 2013) are not public. Each ``*-top``/``*-side``
scenario is a *synthetic replica* calibrated to what the paper reports for that data set
(Table I and footnote 1 of §VIII, §III-B): peak-to-peak amplitude, RMS where reported, sensor
rate, duration and heart-rate profile. ``mitral-1d`` is a replica of the mitral-annulus motion
of Yuen et al. (IJRR 2009 §2). Nothing here is measured data.

Statistics are defined as in :mod:`rhmpc.sim.heart.analysis`: peak-to-peak is the largest per-axis
range max_d (max_t p_d − min_t p_d); RMS is the 3-D RMS about the mean √(mean_t ‖p − p̄‖²).
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from rhmpc.sim.heart.arrhythmia import SHARED_DATA, premature_stroke, record_beats
from rhmpc.sim.heart.invivo import InVivoSettings, invivo_motion
from rhmpc.sim.heart.motion import (
    EPICARDIAL_BUMPS,
    MITRAL_BUMPS,
    MotionSource,
    SyntheticHeartMotion,
    fourier_from_bumps,
)
from rhmpc.sim.heart.rr import (
    PhaseTrack,
    StaircaseProfile,
    beat_times_from_annotations,
    beat_times_from_rr,
    constant_phase,
    staircase_phase,
)
from rhmpc.sim.heart.specs import (
    DEFAULT_SCENARIO,
    DEFAULT_SEED,
    NEEDS_DATA,
    SCENARIOS,
    SPECS,
    ScenarioSpec,
    available_scenarios,
    missing_data,
)
from rhmpc.sim.heart.variability import (
    VariabilitySettings,
    breathing_phase,
    modulated_phase,
    variations,
)

__all__ = ["DEFAULT_SCENARIO", "DEFAULT_SEED", "NEEDS_DATA", "OVERRIDES", "SCENARIOS", "SPECS",
           "Scenario", "ScenarioSpec", "available_scenarios", "calibrate", "make_scenario",
           "missing_data"]

#: Per-site geometry: heartbeat axis weights (x, y, z), breathing direction (x, y, z), the
#: breathing range on its main axis relative to the heartbeat range on the heart's main axis,
#: and the second breathing harmonic relative to the first (Tuna §III-B: "significant first
#: harmonic"). Breathing (along one oblique direction) and heartbeat mostly move different
#: axes, so the three axes have comparable ranges, as the reported RMS/p-p ratios (3.55/8.39,
#: 3.38/7.43) require.
_SITES = {
    "top": dict(heart=(0.45, 0.9, 1.0), breath=(1.0, 0.8, 0.1), breath_ratio=1.0,
                breath_h2=0.35),
    "side": dict(heart=(1.0, 0.9, 0.45), breath=(0.1, 0.8, 1.0), breath_ratio=1.0,
                 breath_h2=0.35),
}
_EPICARDIAL_HARMONICS = 20
_MITRAL_HARMONICS = 12


@dataclass(frozen=True)
class Scenario:
    """A ready-to-run heart-motion scenario.

    Attributes
    ----------
    name : str
        Scenario name.
    source : MotionSource
        The true point-of-interest motion, ``source.position(t)`` [m].
    sensor_rate : float
        Rate of the sensor that recorded the replicated data [Hz].
    duration : float
        Run length [s].
    description : str
        What it replicates.
    spec : ScenarioSpec
        The targets it was calibrated to.
    """

    name: str
    source: MotionSource
    sensor_rate: float
    duration: float
    description: str
    spec: ScenarioSpec

    @property
    def dim(self) -> int:
        """Number of motion axes."""
        return int(self.source.dim)


#: The variability of a spec's own (its band powers), unless the overrides name one.
_OWN = object()

#: Keyword overrides :func:`make_scenario` accepts.
OVERRIDES: tuple[str, ...] = (
    "duration", "sensor_rate", "heart_rate", "peak_to_peak", "rms", "rr", "rr_start",
    "beat_times", "record", "staircase", "breathing_rate", "coupling", "beat_gain_std",
    "breathing", "variability",
)


def make_scenario(name: str, rng: np.random.Generator | None = None, **overrides) -> Scenario:
    """Build the named scenario, calibrated to its targets.

    Parameters
    ----------
    name : str
        One of :data:`SCENARIOS`.
    rng : numpy.random.Generator, optional
        Draws the beat-to-beat variability and the initial phases. ``None`` uses
        ``default_rng(DEFAULT_SEED)``, so the named replica is reproducible.
    **overrides
        ``duration`` [s], ``sensor_rate`` [Hz], ``heart_rate`` [Hz] (constant rate),
        ``staircase`` (:class:`~rhmpc.sim.heart.rr.StaircaseProfile`), ``rr`` (RR intervals [s])
        with ``rr_start`` (time of the first beat [s], default 0), ``beat_times`` [s], ``record``
        (PhysioNet record path: its annotated beat times, shifted so the first beat is at
        ``rr_start``), ``peak_to_peak`` [m], ``rms`` [m or None], ``breathing_rate`` [Hz],
        ``coupling`` [-], ``beat_gain_std`` [-], ``breathing`` (False removes it),
        ``variability`` (:class:`~rhmpc.sim.heart.variability.VariabilitySettings`, or ``"clean"``
        for the periodic replica; default ``VariabilitySettings()``: HRV, beat-to-beat stroke and
        timing, breath period and depth, drift, coupling — except ``mitral-1d``, periodic by
        default because Yuen et al.'s §III-D studies perturb that signal themselves: noise,
        heart-rate steps, RR intervals). ``coupling`` and
        ``beat_gain_std`` override the fields of the same name. Beat-time driven phases
        (``rr``, ``beat_times``, ``record``) carry their own RR variability: no HRV is added.

    Returns
    -------
    Scenario
        With a :class:`~rhmpc.sim.heart.motion.SyntheticHeartMotion` source whose heart phase
        satisfies φ(t_i) = i at the given beat times, or φ(t) = φ₀ + ∫ f_h dτ for rate profiles.

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones) or unknown/invalid override.
    """
    spec, duration, sensor_rate = _spec(name, overrides)
    rng = np.random.default_rng(DEFAULT_SEED) if rng is None else rng
    nominal = spec.duration
    horizon = max(duration, nominal)
    if spec.heart == "invivo":
        return _invivo(spec, overrides, rng, duration, sensor_rate, horizon)
    settings = _variability(spec, overrides)
    beats, stroke = _beats(spec, overrides)
    breathing_rate = float(overrides.get("breathing_rate", 1.0 / 6.0))
    breath = None if settings.is_clean else breathing_phase(rng, breathing_rate, horizon,
                                                            settings.breath_period_cv)
    phase = _phase(spec, overrides, rng, horizon, settings, breath, beats)
    if beats is not None and "duration" not in overrides:
        duration = min(nominal, float(beats[-1] - max(beats[0], 0.0)))
    shape = _shape(spec, overrides, rng, phase, horizon, settings, breath, stroke)
    calib_t = np.arange(round(nominal * spec.sensor_rate) + 1) / spec.sensor_rate
    source = calibrate(shape, calib_t, spec.peak_to_peak, spec.rms)
    described = spec.description + (" [RR-driven]" if beats is not None else "")
    return Scenario(name, source, sensor_rate, duration, described, spec)


def _spec(name: str, overrides: dict) -> tuple[ScenarioSpec, float, float]:
    """The named spec with the overrides of its fields, the run's duration [s] and the sensor
    rate [Hz]; an unknown name or override, or a duration or rate ≤ 0, is a ``ValueError``."""
    if name not in SPECS:
        raise ValueError(f"unknown scenario {name!r}; valid names: {', '.join(SCENARIOS)}")
    unknown = sorted(set(overrides) - set(OVERRIDES))
    if unknown:
        raise ValueError(f"unknown scenario override(s) {', '.join(unknown)}; "
                         f"valid: {', '.join(OVERRIDES)}")
    spec_fields = {f.name for f in fields(ScenarioSpec)}
    spec = replace(SPECS[name], **{k: v for k, v in overrides.items()
                                   if k in spec_fields and k not in {"duration", "sensor_rate"}})
    duration = float(overrides.get("duration", spec.duration))
    sensor_rate = float(overrides.get("sensor_rate", spec.sensor_rate))
    if not duration > 0 or not sensor_rate > 0:
        raise ValueError("duration and sensor_rate must be positive")
    return spec, duration, sensor_rate


def _invivo(spec: ScenarioSpec, overrides: dict, rng: np.random.Generator, duration: float,
            sensor_rate: float, horizon: float) -> Scenario:
    """The in-vivo regime of :mod:`rhmpc.sim.heart.invivo` (overrides: ``heart_rate``,
    ``breathing_rate``)."""
    unsupported = sorted(set(overrides) - {"duration", "sensor_rate", "heart_rate",
                                           "breathing_rate"})
    if unsupported:
        raise ValueError(f"{spec.name} takes no override(s) {', '.join(unsupported)}")
    changes = {k: float(overrides[k]) for k in ("heart_rate", "breathing_rate") if k in overrides}
    source = invivo_motion(rng, horizon, spec.duration, InVivoSettings(**changes))
    return Scenario(spec.name, source, sensor_rate, duration, spec.description, spec)


def _variability(spec: ScenarioSpec, overrides: dict) -> VariabilitySettings:
    """The variability settings (the spec's own, or the ``variability`` override) with the
    ``coupling``/``beat_gain_std`` overrides applied."""
    value = overrides.get("variability", _OWN if spec.variable else "clean")
    if value is _OWN:
        bands = {} if spec.hrv_band_powers is None else {"band_powers": spec.hrv_band_powers}
        value = VariabilitySettings(**bands)
    elif isinstance(value, str):
        if value != "clean":
            raise ValueError(f"variability must be a VariabilitySettings or 'clean', got {value!r}")
        value = VariabilitySettings.clean()
    if not isinstance(value, VariabilitySettings):
        raise ValueError(f"variability must be a VariabilitySettings or 'clean', got {value!r}")
    changes = {k: float(overrides[k]) for k in ("coupling", "beat_gain_std") if k in overrides}
    if spec.site == "mitral":
        changes = {"coupling": 0.0, **changes}
    return replace(value, **changes) if changes else value


def _beats(spec: ScenarioSpec, overrides: dict) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The beat times [s] that drive the heart phase, if any (``beat_times``, ``rr`` with
    ``rr_start``, ``record``, or the spec's own record), and the stroke gain of each of the
    spec's record's beats (:func:`~rhmpc.sim.heart.arrhythmia.premature_stroke`; None otherwise)."""
    start = float(overrides.get("rr_start", 0.0))
    if "beat_times" in overrides:
        return np.asarray(overrides["beat_times"], dtype=float), None
    if "rr" in overrides:
        return beat_times_from_rr(overrides["rr"], start), None
    if "record" in overrides:
        raw = beat_times_from_annotations(Path(overrides["record"]))
        return raw - raw[0] + start, None
    if spec.heart != "record":
        return None, None
    times, premature = record_beats(SHARED_DATA / str(spec.record), spec.record_start,
                                    spec.duration, spec.name)
    return times, premature_stroke(times, premature)


def _phase(spec: ScenarioSpec, overrides: dict, rng: np.random.Generator, horizon: float,
           settings: VariabilitySettings, breath: PhaseTrack | None,
           beats: np.ndarray | None) -> PhaseTrack:
    """The heart phase: through the beat times ``beats``, else φ₀ ~ U(0, 1) plus the integral
    of the constant rate or the staircase, with HRV when there is any and a breathing phase."""
    if beats is not None:
        return PhaseTrack.from_beat_times(beats)
    phase0 = float(rng.random())
    constant = "heart_rate" in overrides or spec.heart == "constant"
    staircase = overrides.get("staircase", StaircaseProfile())
    if constant:
        rate = float(spec.heart_rate)
        if not rate > 0:
            raise ValueError("heart_rate must be positive [Hz]")
        knots = (np.array([0.0, 1.0]), np.array([rate, rate]))
    else:
        knots = staircase.knots(horizon)
    if settings.hrv_cv > 0 and breath is not None:
        return modulated_phase(rng, *knots, horizon, settings, breath, phase0)
    if constant:
        return constant_phase(float(knots[1][0]), phase0)
    return staircase_phase(staircase, horizon, phase0)


def _shape(spec: ScenarioSpec, overrides: dict, rng: np.random.Generator, phase: PhaseTrack,
           horizon: float, settings: VariabilitySettings, breath: PhaseTrack | None,
           stroke: np.ndarray | None) -> SyntheticHeartMotion:
    """The uncalibrated motion for ``spec`` (unit-less shape, scaled later): the site's beat
    and breathing coefficients (the breathing's phase ψ drawn), then the variations of the
    beats and breaths (:func:`~rhmpc.sim.heart.variability.variations`), each beat's gain times its
    ``stroke`` (beat 0 the record's first)."""
    breathing_rate = float(overrides.get("breathing_rate", 1.0 / 6.0))
    with_breathing = bool(overrides.get("breathing", spec.site != "mitral"))
    if spec.site == "mitral":
        heart = fourier_from_bumps(MITRAL_BUMPS, _MITRAL_HARMONICS)[None, :]
        breathing = np.zeros((1, 2), dtype=complex)
        if with_breathing:
            breathing[0, 0] = 0.15 * np.max(np.abs(heart))
    else:
        site = _SITES[spec.site]
        heart = np.stack([w * fourier_from_bumps(b, _EPICARDIAL_HARMONICS)
                          for w, b in zip(site["heart"], EPICARDIAL_BUMPS, strict=True)])
        dominant = int(np.argmax(site["heart"]))
        h_range = _range_of(heart[dominant])
        direction = np.asarray(site["breath"], dtype=float)
        a1 = 0.5 * site["breath_ratio"] * h_range * direction / np.max(direction)
        psi = 2 * np.pi * rng.random()
        h2 = site["breath_h2"] * a1 * np.exp(1j * (2 * psi + 0.6))
        breathing = np.stack([a1 * np.exp(1j * psi), h2], axis=1)
        if not with_breathing:
            breathing = np.zeros_like(breathing)
    first = int(np.floor(float(phase(-5.0))))
    last = int(np.ceil(float(phase(horizon + 5.0))))
    heart_range = max(_range_of(c) for c in heart) if settings.drift_std > 0 else 0.0
    drawn = variations(rng, settings, last - first + 1, heart.shape[0], breath, horizon,
                       heart_range)
    if stroke is not None:
        beat = np.arange(first, last + 1)
        drawn["beat_gains"] = drawn["beat_gains"] * stroke[np.clip(beat, 0,
                                                                   stroke.size - 1)][:, None]
    return SyntheticHeartMotion(phase, heart, breathing, breathing_rate, settings.coupling,
                                first_beat=first, **drawn)


def _range_of(coef: np.ndarray) -> float:
    """Peak-to-peak of Re Σ c_k e^{i2πkφ} over one cycle."""
    phi = np.arange(2048) / 2048
    k = np.arange(1, coef.size + 1)
    y = (np.exp(2j * np.pi * np.outer(phi, k)) @ coef).real
    return float(y.max() - y.min())


def calibrate(motion: SyntheticHeartMotion, t: np.ndarray, peak_to_peak: float,
              rms: float | None = None) -> SyntheticHeartMotion:
    """Scale ``motion`` so that, sampled at ``t``, its statistics hit the targets.

    The largest per-axis range is set to ``peak_to_peak``. If ``rms`` is given, the axes other
    than the dominant one are first scaled by a common factor s so that
    √(Σ_d var_d) / range_dom = rms / peak_to_peak (kept below the dominant range).

    Parameters
    ----------
    motion : SyntheticHeartMotion
        Uncalibrated motion.
    t : ndarray, shape (n,)
        Sample times of the reference recording [s].
    peak_to_peak : float
        Target [m].
    rms : float, optional
        Target 3-D RMS about the mean [m].
    """
    p = motion.position(t)
    ranges = np.ptp(p, axis=0)
    var = np.var(p, axis=0)
    dom = int(np.argmax(ranges))
    factor = np.ones(motion.dim)
    others = np.arange(motion.dim) != dom
    if rms is not None and motion.dim > 1 and np.sum(var[others]) > 0:
        need = (rms / peak_to_peak) ** 2 * ranges[dom] ** 2 - var[dom]
        s = np.sqrt(max(need, 0.0) / np.sum(var[others]))
        s = min(s, ranges[dom] / np.max(ranges[others]))
        factor[others] = s
    factor *= peak_to_peak / ranges[dom]
    return motion.scaled(factor)
