"""A run as a MAT file (rhmpc.report.matlab): what MATLAB's ``load`` finds in it."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.io import loadmat

from rhmpc.report.matlab import field_name, matlab_value, write_mat
from tests.rhmpc.report.stand_in_run import stand_in_run

DOC = {
    "predictor": "generalized", "rms_error_mm": 0.123, "saturated_ticks": 3,
    "settings": {"loop": {"duration": 3.0, "poi_offset": [0.0, 0.0, 0.001]}},
    "tick_us": {"p50": 12.0, "p99.9": 40.0}, "heart_rate": {"lock_time_s": None},
    "flags": [True, False], "events": [{"a": 1}, {"b": "x"}], "1st": 1,
}


@pytest.fixture(scope="module")
def run(phantom) -> SimpleNamespace:
    return stand_in_run(phantom, seconds=2.0)


def test_loadmat_finds_the_time_the_error_and_the_trace(tmp_path, run) -> None:
    m = loadmat(write_mat(tmp_path / "run.mat", run, DOC))
    n = run.time.size
    assert m["time"].shape == (n, 1) and np.allclose(m["time"][:, 0], run.time)
    assert np.allclose(m["error"], run.ee - run.poi)
    assert np.allclose(m["error_norm"][:, 0], np.linalg.norm(run.ee - run.poi, axis=1))
    for name in ("ee", "poi", "reference0", "tau_mpc", "tau", "tau_command", "q"):
        assert m[name].shape == (n, 3), name
    R, N, _ = run.horizons[1].shape
    assert m["horizon"].shape == (R, N, 3)
    assert np.allclose(m["horizon_time"][:, 0], run.horizons[0] * run.settings.Ts)
    assert m["sample"].shape == (run.samples[0].size, 3)
    assert m["units"]["error"][0, 0][0] == "m" and m["units"]["tau"][0, 0][0] == "N*m"


def field(struct, *names):
    """A nested field of a struct as loadmat gives it (1 × 1 arrays of records)."""
    for name in names:
        struct = struct[0, 0][name]
    return struct


def test_the_summary_is_a_struct_of_doubles_and_the_document_verbatim(tmp_path, run) -> None:
    s = loadmat(write_mat(tmp_path / "run.mat", run, DOC))["summary"]
    assert field(s, "rms_error_mm")[0, 0] == 0.123
    assert field(s, "saturated_ticks").dtype == np.float64  # int64 would round in MATLAB
    assert field(s, "tick_us", "p99_9")[0, 0] == 40.0
    assert field(s, "heart_rate", "lock_time_s").size == 0  # null -> []
    assert field(s, "flags").dtype == np.uint8  # logical
    assert field(s, "x1st")[0, 0] == 1.0
    assert np.allclose(field(s, "settings", "loop", "poi_offset").ravel(), [0, 0, 0.001])
    assert field(s, "predictor")[0] == "generalized"


def test_the_document_is_there_verbatim(tmp_path, run) -> None:
    m = loadmat(write_mat(tmp_path / "run.mat", run, DOC))
    assert json.loads(str(m["summary_json"][0])) == DOC


def test_a_run_without_forecasts_or_samples_still_writes(tmp_path, run) -> None:
    bare = SimpleNamespace(**{k: v for k, v in vars(run).items()
                              if k not in ("horizons", "samples")})
    m = loadmat(write_mat(tmp_path / "bare.mat", bare, {"rms_error_mm": 1.0}))
    assert "time" in m and "error" in m and "horizon" not in m and "sample" not in m


@pytest.mark.parametrize(("key", "name"), [
    ("p99.9", "p99_9"), ("1st", "x1st"), ("rms error", "rms_error"), ("ω", "x_"),
    ("a" * 80, "a" * 63), ("", "x"),
])
def test_field_names_are_matlab_identifiers(key: str, name: str) -> None:
    assert field_name(key) == name


def test_colliding_names_get_a_suffix() -> None:
    assert list(matlab_value({"a.b": 1, "a_b": 2})) == ["a_b", "a_b_2"]
