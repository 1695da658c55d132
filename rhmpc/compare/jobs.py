"""The runs of a comparison: one closed-loop run per predictor × column × seed.

A *column* is a scenario, a recording (its file name) or one tracked point of it
(``rec.mat:p2``), with the settings that make a run of it (:func:`scenario_columns`,
:func:`data_columns`); :func:`make_jobs` crosses the columns with the predictors and the seeds
into :class:`Job` s, each run by :func:`run_job` in a worker. A run that fails is a document
with ``error`` (:func:`failed_doc`): one failed cell never loses the others.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.config import with_split
from rhmpc.experiment.fitting import with_models

__all__ = ["DATA_PREDICTORS", "TABLE_PREDICTORS", "Column", "Job", "check_predictors",
           "data_columns", "evaluate_job", "failed_doc", "labelled", "make_jobs", "run_job",
           "scenario_columns", "setting_of"]

#: The predictors on scenarios: Tuna et al.'s rows and the EKF.
TABLE_PREDICTORS = ("exact", "one-step", "generalized", "ekf")
#: The predictors on recordings: ``hold`` first, the ratios' yardstick there.
DATA_PREDICTORS = ("hold", "exact", "one-step", "generalized", "ekf")

class Column(NamedTuple):
    """A column of the table: its label, and the settings that make a run of it (dotted
    keys)."""

    label: str
    changes: dict


@dataclass(frozen=True)
class Job:
    """One closed-loop run of the table.

    Attributes
    ----------
    key : str
        Its place in the table's order (unique among the jobs).
    column : str
        The table's column: a scenario, a recording (its file name), or one tracked point of
        it (``rec.mat:p2``).
    config : RunConfig
        The run's settings.
    """

    key: str
    column: str
    config: RunConfig


def run_job(job: Job) -> dict:
    """Run one job (in a worker): its document, or a failed one with ``error``."""
    try:
        doc = run_experiment(job.config)[1]
    except Exception as exc:  # one failed cell must not lose the others
        doc = failed_doc(job, f"{type(exc).__name__}: {exc}")
    return labelled(doc, job)


def evaluate_job(job: Job, extra: dict | None = None) -> dict:
    """The sweep runner's evaluation: :func:`run_job` (looked up when called, so that a test
    may stand in for it), one at a time per process, as ``rhmpc tune``'s evaluations."""
    from rhmpc.tuning.evaluate import RUN_LOCK

    with RUN_LOCK:
        return run_job(job)


def failed_doc(job: Job, error: str) -> dict:
    """The document of a run that failed: its predictor, seed, settings and ``error``."""
    from rhmpc.experiment.run import jsonable

    config = job.config
    return {"predictor": config.predictor, "seed": config.seed, "error": error,
            "settings": jsonable(config.to_dict())}


def labelled(doc: dict, job: Job) -> dict:
    """``doc`` with its column (``scenario``) and, on a recording, its file and point."""
    doc["scenario"] = job.column
    if job.config.data is not None:
        doc["data"] = job.config.data
        doc["point"] = job.config.data_read.get("point")
    return doc


def setting_of(configs: Sequence[RunConfig]) -> str:
    """Tuna's setting of runs: ``hardware`` when every plant is the hardware-like one, else
    ``simulation``."""
    plants = {c.plant.label for c in configs}
    return "hardware" if plants == {"hardware"} else "simulation"


def check_predictors(names: Sequence[str]) -> list[str]:
    """``names`` without blanks and repeats, each a registered predictor (else a one-line
    :class:`UsageError` naming the valid ones)."""
    from rhmpc.predictors import predictor_names

    predictors = list(dict.fromkeys(p.strip() for p in names if p.strip()))
    bad = [p for p in predictors if p not in predictor_names()]
    if bad:
        raise UsageError(f"unknown predictor(s) {', '.join(bad)}; valid: "
                         f"{', '.join(predictor_names())}")
    return predictors


def make_jobs(base: RunConfig, columns: Sequence[Column], predictors: Sequence[str],
              seeds: Sequence[int], models: Sequence[str] = ()) -> list[Job]:
    """One :class:`Job` per column × predictor × seed, in the table's order: ``base`` with the
    column's settings, the predictor and the seed; ``models``, saved models a run of their
    kind loads instead of fitting (:func:`rhmpc.experiment.fitting.with_models`)."""
    out = []
    for column, changes in columns:
        run_base = base.replace(**changes)
        for predictor in predictors:
            for seed in seeds:
                config = run_base.replace(predictor=predictor, seed=seed)
                out.append(Job(str(len(out)), column, with_models(config, models, strict=False)))
    return out


def scenario_columns(names: Sequence[str], full: bool = False) -> list[Column]:
    """A column per scenario; ``full``: each runs its scenario's whole duration."""
    from rhmpc.sim.heart import SCENARIOS, SPECS

    scenarios = list(dict.fromkeys(s.strip() for s in names if s.strip()))
    unknown = [s for s in scenarios if s not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario(s) {', '.join(unknown)}; valid: {', '.join(SCENARIOS)}")
    return [Column(s, {"scenario": s, **({"loop.duration": SPECS[s].duration} if full else {})})
            for s in scenarios]


def data_columns(data: Sequence[str], options: dict, points: str | None, recorded: bool,
                 split: tuple[int, int] | None = None, duration: float | None = None,
                 whole: bool = True) -> list[Column]:
    """A column per recording, or per tracked point of one.

    Parameters
    ----------
    data : sequence of str
        The recordings: files, or the names of shipped ones
        (:func:`rhmpc.sim.recordings.shipped.resolve_all`).
    options : dict
        How to read them (``load_recording``'s keywords given on the command line).
    points : str or None
        ``all`` or ``N[,N...]``: a column per tracked point (numbered from 1); None: each
        file's own point of interest where it names one (a shipped recording), else the file.
    recorded : bool
        Whether the sensor is the recording's own samples (``sensor = "recorded"``).
    split : (int, int) or None
        The literature's split (TRAIN, END): the settling and the duration follow from it.
    duration : float or None
        ``--duration`` [s]; a recording shorter than it is a :class:`UsageError`.
    whole : bool
        Without ``split`` or ``duration``: run each recording whole.
    """
    from rhmpc.openloop.tracks import file_points, parse_points
    from rhmpc.sim.recordings.shipped import resolve_all

    try:
        paths, read, poi = resolve_all(data, options)
        if points is None and poi is not None:
            points = str(poi)
        files = file_points(paths, parse_points(points), read)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    sensor = {"sensor": "recorded"} if recorded else {}
    out = []
    for group in files:
        for column, path, point, recording in group:
            changes = {"data": path, "data_read": {**read, **({"point": point} if point else {})},
                       **sensor}
            if split:
                span = with_split(RunConfig(data=path, data_read=changes["data_read"]), split).loop
                changes.update({"loop.settling": span.settling, "loop.duration": span.duration})
            elif duration is None and whole:
                changes["loop.duration"] = recording.duration
            elif duration is not None and duration > recording.duration:
                raise UsageError(f"{path}: the recording lasts {recording.duration:.2f} s, "
                                 f"--duration asks for {duration:.2f} s")
            out.append(Column(column, changes))
    return out
