"""The closed loop beside the open loop on the same samples (rhmpc.compare.loop_gap)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.compare.loop_gap import beside_plan, open_loop_beside, open_names
from rhmpc.predictors.registry import combination_members
from rhmpc.sim.recordings import load_points
from rhmpc.sim.recordings.shipped import SHIPPED

PHANTOM = SHIPPED["hamlyn-phantom"]


def test_the_combination_brings_its_members_and_exact_stays_out():
    names = open_names(["hold", "exact", "combination"])
    assert names[0] == "hold" and names[-1] == "combination" and "exact" not in names
    assert set(combination_members()) <= set(names)


def test_the_open_loop_forecasts_the_scored_samples_one_ahead():
    """hold forecasts z_{k−1} for z_k: its figure is the RMS step of samples TRAIN … END − 1,
    computed here from the file."""
    z = load_points(PHANTOM.path, **PHANTOM.read)[3].z
    plan = beside_plan(str(PHANTOM.path), {**PHANTOM.read, "point": 4}, (100, 150), ["hold"],
                       leads=4)
    got = open_loop_beside(plan)["hold"]
    step = np.linalg.norm(z[100:150] - z[99:149], axis=1)
    np.testing.assert_allclose(got["rms_error_mm"], 1e3 * np.sqrt(np.mean(step**2)), rtol=1e-12)
    assert got["scored"] == 50


@pytest.mark.slow
def test_compare_sets_each_closed_loop_beside_its_open_loop(capsys):
    assert main(["compare", "--data", "hamlyn-phantom", "--poi", "4", "--split", "100:150",
                 "--predictors", "hold,one-step", "--jobs", "1", "--json", "--quiet"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rows = {r["predictor"]: r for r in doc["loop_gap"]}
    assert set(rows) == {"hold", "one-step"}
    for r in rows.values():
        assert r["scored_samples"] == 50 and r["closed_to_open"] > 0
        np.testing.assert_allclose(r["closed_to_open"], r["closed_rms_mm"] / r["open_rms_mm"])
    assert all(run["score"] == "measured" for run in doc["runs"])
