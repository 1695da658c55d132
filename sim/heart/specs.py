"""The named scenarios' specifications: what the papers report for each data set replicated.

:class:`ScenarioSpec` is the calibration target and the heart-rate profile of one replica;
:data:`SPECS` holds them by name. :mod:`rhmpc.sim.heart.scenarios` builds the motion from a spec.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from rhmpc.sim.heart.arrhythmia import SHARED_DATA

#: The seed used when :func:`make_scenario` is given no generator, so that a named replica is
#: the same everywhere unless a caller asks for another draw.
DEFAULT_SEED = 20130201


@dataclass(frozen=True)
class ScenarioSpec:
    """What a named scenario replicates (the values reported by the paper) and its shape.

    Attributes
    ----------
    name : str
        Scenario name.
    description : str
        One line: what it replicates and which values are assumed.
    peak_to_peak : float
        Target largest per-axis peak-to-peak amplitude [m].
    rms : float or None
        Target 3-D RMS about the mean [m]; None keeps the shape's own ratio.
    sensor_rate : float
        Sample rate of the recording/sensor [Hz].
    duration : float
        Duration [s].
    heart : str
        ``"constant"``, ``"staircase"``, ``"record"`` or ``"invivo"``
        (:mod:`rhmpc.sim.heart.invivo`).
    heart_rate : float
        Heart rate for ``"constant"`` [Hz] (the first staircase level otherwise).
    site : str
        ``"top"``, ``"side"`` (epicardial, 3-D), ``"mitral"`` (1-D) or ``"invivo"``.
    reported : tuple of str
        Which of ``peak_to_peak``, ``rms``, ``heart_rate``, ``sensor_rate``, ``duration`` come
        from the paper (the rest are assumptions).
    record : str or None
        For ``heart="record"``: the PhysioNet record (relative to the shared data folder) whose
        annotated beats drive the heart phase.
    record_start : float
        Time in the record where the scenario starts [s].
    variable : bool
        Whether the default is the physiological variability of :mod:`rhmpc.sim.heart.variability`
        (True) or the periodic replica (False).
    hrv_band_powers : tuple of float or None
        Relative VLF/LF/HF powers of the default heart-rate variability
        (:attr:`~rhmpc.sim.heart.variability.VariabilitySettings.band_powers`; its total ``hrv_cv``
        is kept); ``None``: the Task Force norms.
    """

    name: str
    description: str
    peak_to_peak: float
    rms: float | None
    sensor_rate: float
    duration: float
    heart: str
    heart_rate: float
    site: str
    reported: tuple[str, ...] = field(default=())
    record: str | None = None
    record_start: float = 0.0
    variable: bool = True
    hrv_band_powers: tuple[float, float, float] | None = None

    @property
    def dim(self) -> int:
        """Number of motion axes: 1 at the mitral annulus (along its axis), else 3."""
        return 1 if self.site == "mitral" else 3


_SPECS: tuple[ScenarioSpec, ...] = (
    ScenarioSpec(
        "fixed-a1-top", "Tuna et al. animal 1, crystal on top, constant heart rate (replica; "
        "heart rate 95 bpm assumed)", 12.19e-3, None, 404.0, 235.0,
        "constant", 1.58, "top", ("peak_to_peak", "sensor_rate", "duration")),
    # Tuna §III-B: the constant-rate record's heart line is sharp at 1.66 Hz over 472 s ("the
    # harmonics decay very little in time"), so its rate variability is respiratory (the HF
    # band, at the ventilator's rate) and not the VLF/LF wander that moves a 40-s mean rate
    # by ±0.1 Hz: all of the 6 % HRV is put in the HF band.
    ScenarioSpec(
        "fixed-a2-top", "Tuna et al. animal 2, crystal on top, constant 100 bpm (replica of "
        "§III-B: p-p 8.39 mm, RMS 3.55 mm)", 8.39e-3, 3.55e-3, 257.0, 472.0, "constant",
        100.0 / 60.0, "top", ("peak_to_peak", "rms", "heart_rate", "sensor_rate", "duration"),
        hrv_band_powers=(0.0, 0.0, 975.0)),
    ScenarioSpec(
        "varying-a1-top", "Tuna et al. animal 1, crystal on top, pacemaker staircase 95–152 bpm "
        "(replica)", 13.75e-3, None, 404.0, 251.0,
        "staircase", 1.58, "top", ("peak_to_peak", "heart_rate", "sensor_rate", "duration")),
    ScenarioSpec(
        "varying-a3-top", "Tuna et al. animal 3, crystal on top, pacemaker staircase 95–152 bpm "
        "(replica of §III-B: p-p 7.43 mm, RMS 3.38 mm)", 7.43e-3, 3.38e-3, 404.0, 200.0,
        "staircase", 1.58, "top",
        ("peak_to_peak", "rms", "heart_rate", "sensor_rate", "duration")),
    ScenarioSpec(
        "varying-a1-side", "Tuna et al. animal 1, crystal on the side, pacemaker staircase "
        "(replica)", 13.39e-3, None, 404.0, 250.0,
        "staircase", 1.58, "side", ("peak_to_peak", "heart_rate", "sensor_rate", "duration")),
    ScenarioSpec(
        "varying-a3-side", "Tuna et al. animal 3, crystal on the side, pacemaker staircase "
        "(replica; the record ends during the descent)", 7.96e-3,
        None, 404.0, 140.0, "staircase", 1.58, "side",
        ("peak_to_peak", "heart_rate", "sensor_rate", "duration")),
    ScenarioSpec(
        "mitral-1d", "Yuen et al. mitral annulus along its axis, 1-D: 20 mm travel, "
        "60 bpm (210 mm/s and 3.8 m/s² peaks at 76 bpm; replica)", 20e-3, None, 28.0, 40.0,
        "constant", 1.0, "mitral", ("peak_to_peak",), variable=False),
    ScenarioSpec(
        "arrhythmia-apb", "fixed-a2-top's motion driven by MIT-BIH record 100 (1035–1275 s: "
        "10 of its 33 atrial premature beats), premature beats with a smaller stroke and the "
        "pause after them (replica; real annotations, synthetic motion)", 8.39e-3, 3.55e-3,
        257.0, 240.0, "record", 100.0 / 60.0, "top", ("peak_to_peak", "rms", "sensor_rate"),
        record="mitdb-100/100", record_start=1035.0),
    ScenarioSpec(
        "invivo-video", "in-vivo regime: breathing-dominated 3-D epicardial motion at 50 bpm "
        "with large beat-to-beat variation, as tracked by stereo endoscopic video at 25 "
        "frames/s (built from a recording's statistics, rhmpc.sim.heart.invivo)", 5.1e-3, None,
        25.0, 60.0,
        "invivo", 0.83, "invivo", ("peak_to_peak", "heart_rate", "sensor_rate")),
)

SPECS: dict[str, ScenarioSpec] = {s.name: s for s in _SPECS}

#: Scenario names, the default first.
SCENARIOS: tuple[str, ...] = ("fixed-a2-top",
                              *(s.name for s in _SPECS if s.name != "fixed-a2-top"))

#: The named scenarios that need the shared real data (skipped where it is absent).
NEEDS_DATA: tuple[str, ...] = tuple(s.name for s in _SPECS if s.record is not None)


def missing_data(name: str) -> Path | None:
    """The annotation file scenario ``name`` needs and cannot find, or ``None`` if it can run."""
    if name not in NEEDS_DATA:
        return None
    path = (SHARED_DATA / str(SPECS[name].record)).with_suffix(".atr")
    return None if path.is_file() else path


def available_scenarios() -> tuple[str, ...]:
    """The named scenarios that can run here (those needing absent shared data left out)."""
    return tuple(name for name in SCENARIOS if missing_data(name) is None)

DEFAULT_SCENARIO = "fixed-a2-top"
