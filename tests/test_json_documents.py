"""The JSON documents of simulate, compare and predict against their page (docs/guide/json.md):
every key a document carries is listed there, every key listed as always there is carried, and
each document's ``schema`` is its section's, named in the changelog."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "guide" / "json.md"


def documented() -> dict[str, dict[str, set[str]]]:
    """schema → {"always": keys, "any": keys} from the page's tables (a cell may list several
    keys), and for the open-loop study its ``sources`` and ``results`` lists."""
    out: dict[str, dict[str, set[str]]] = {}
    for section in PAGE.read_text(encoding="utf-8").split("\n## ")[1:]:
        schema = re.match(r"`([^`]+)`", section).group(1)
        keys = {"always": set(), "any": set()}
        for row in re.findall(r"^\| (`[^|]+) \| ([^|]+) \|", section, re.M):
            names = set(re.findall(r"`([^`]+)`", row[0]))
            keys["any"] |= names
            if row[1].strip() == "always":
                keys["always"] |= names
        for part in ("sources", "results"):
            m = re.search(rf"^Each of `{part}`: (.*?)(?:\n\n|\Z)", section, re.M | re.S)
            if m:
                keys[part] = set(re.findall(r"`([a-z_0-9]+)`", m.group(1)))
        out[schema] = keys
    return out


def check(doc: dict, schema: str) -> None:
    keys = documented()[schema]
    assert doc["schema"] == schema
    assert set(doc) - keys["any"] == set(), "add these keys to docs/guide/json.md"
    assert keys["always"] - set(doc) == set(), "these keys are listed as always there"


def test_each_schema_is_named_in_the_changelog() -> None:
    from rhmpc.compare.runs import SCHEMA as COMPARE
    from rhmpc.experiment.run import SCHEMA as SIMULATE
    from rhmpc.openloop.recordings import SCHEMA as RECORDINGS
    from rhmpc.openloop.studies import SCHEMA as STUDY

    changelog = (REPO / "CHANGELOG.md").read_text(encoding="utf-8")
    assert set(documented()) == {SIMULATE, COMPARE, RECORDINGS, STUDY}
    for schema in documented():
        assert f"`{schema}`" in changelog, f"a changelog line names {schema}"


@pytest.mark.slow
def test_a_run_document_is_the_documented_one() -> None:
    from rhmpc.experiment import RunConfig, run_experiment
    from rhmpc.sim.loop import LoopSettings

    _, doc = run_experiment(RunConfig(loop=LoopSettings(duration=1.0, settling=0.5)),
                            gain_tick=True)
    check(json.loads(json.dumps(doc)), "rhmpc.simulate/1")


def test_a_comparison_document_is_the_documented_one(monkeypatch, capsys) -> None:
    from rhmpc.cli import main
    from rhmpc.compare import jobs

    def stand_in(job: jobs.Job) -> dict:
        return jobs.labelled({"schema": "rhmpc.simulate/1", "predictor": job.config.predictor,
                              "seed": job.config.seed, "rms_error_mm": 0.2,
                              "max_error_mm": 0.5, "rms_effort_mNm": 9.0}, job)

    monkeypatch.setattr(jobs, "run_job", stand_in)
    assert main(["compare", "--scenarios", "fixed-a2-top", "--predictors", "hold,exact",
                 "--duration", "1", "--jobs", "1", "--json", "--quiet"]) == 0
    check(json.loads(capsys.readouterr().out), "rhmpc.compare/2")


def test_an_open_loop_document_is_the_documented_one() -> None:
    from rhmpc.openloop.plan import OpenLoopSettings
    from rhmpc.openloop.recordings import run_open_loop
    from rhmpc.openloop.tracks import Track

    t = np.arange(0.0, 16.0, 0.04)
    z = 1e-3 * np.stack([np.sin(7.5 * t), np.cos(7.5 * t), np.sin(1.6 * t)], axis=1)
    doc = run_open_loop([Track("rec", t, z, "rec.csv")],
                        OpenLoopSettings(predictors=("hold", "one-step"), leads=2, warmup=4.0))
    doc = json.loads(json.dumps(doc))
    check(doc, "rhmpc.predict.recordings/1")
    keys = documented()["rhmpc.predict.recordings/1"]
    assert set(doc["sources"][0]) == keys["sources"]
    assert set(doc["results"][0]) <= keys["results"]


def test_a_study_document_is_the_documented_one() -> None:
    from rhmpc.openloop.studies import StudySettings, run_study

    doc = run_study(StudySettings("noise", trials=1, predictors=("one-step",), noise_mm=(1.0,)))
    check(json.loads(json.dumps(doc)), "rhmpc.predict.study/1")
