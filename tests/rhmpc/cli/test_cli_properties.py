"""The command line on generated input (hypothesis): any setting, any file bytes, any results
line is read or refused with exit 2 and one line naming the problem, never a traceback.

Each case runs in-process through :func:`rhmpc.cli.main` and stops before a simulation (a
generated configuration is checked, then the run is stopped by an output it refuses), so the
examples stay within seconds and a few hundred megabytes.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhmpc.cli import main
from rhmpc.experiment.config import FREE_TABLES, SECTIONS
from tests.test_bad_input_table import message_lines

PROPERTY = settings(max_examples=30, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])
ERROR = re.compile(r"^rhmpc [\w ]+: error: \S")

KEYS = st.sampled_from([f"{section}.{field}" for section, cls in SECTIONS.items()
                        for field in cls.__dataclass_fields__]
                       + [f"{t}.model" for t in FREE_TABLES[1:2]]
                       + ["seed", "robot", "predictor", "data", "train", "nosuch.key"])
VALUES = st.one_of(
    st.integers(-10**12, 10**12).map(str), st.floats(allow_nan=True).map(repr),
    st.sampled_from(["true", "[]", "[1, 2]", '"x"', "inf", "-0.0", "1e308", "[[[[1]]]]",
                     '"empty.npz"', "{a = 1}", "nan"]),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=["Cs"]), max_size=12))


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, list[str]]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's refusals
        code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return code, message_lines(err)


def refused_in_one_line(code: int, lines: list[str]) -> None:
    assert code == 2, lines
    errors = [line for line in lines if ERROR.match(line)]
    assert errors == lines[-1:], lines


@PROPERTY
@given(pairs=st.lists(st.tuples(KEYS, VALUES), min_size=1, max_size=3))
def test_any_setting_is_taken_or_refused_in_one_line(tmp_path: Path, monkeypatch,
                                                     capsys, pairs) -> None:
    monkeypatch.chdir(tmp_path)
    argv = ["config", "show"]
    for key, value in pairs:
        argv += ["--set", f"{key}={value}"]
    code, lines = run(argv, capsys)
    if code != 0:
        refused_in_one_line(code, lines)


@PROPERTY
@given(pairs=st.lists(st.tuples(KEYS, VALUES), max_size=2),
       duration=st.one_of(st.floats(allow_nan=True), st.integers(-5, 10**9)).map(str))
def test_a_run_whatever_its_settings_stops_before_it_starts(tmp_path: Path, monkeypatch,
                                                            capsys, pairs, duration) -> None:
    monkeypatch.chdir(tmp_path)
    argv = ["simulate", "--duration", duration, "--view", "replay.txt"]  # refused before a run
    for key, value in pairs:
        argv += ["--set", f"{key}={value}"]
    refused_in_one_line(*run(argv, capsys))


@PROPERTY
@given(data=st.binary(max_size=3000))
def test_any_bytes_as_a_config_file(tmp_path: Path, monkeypatch, capsys, data: bytes) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run.toml").write_bytes(data)
    code, lines = run(["config", "show", "--config", "run.toml"], capsys)
    if code != 0:
        refused_in_one_line(code, lines)
        assert "run.toml" in lines[-1]


FIELD = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                  st.integers(-10**6, 10**6).map(str), st.just(""),
                  st.text(alphabet="0123456789.,e-x# \"", max_size=6))


@PROPERTY
@given(header=st.sampled_from(["t,x,y,z", "t_ms,x,y,z", "t,x", "t,x1,y1,z1,x2,y2,z2",
                               "time,x,y,z", ""]),
       rows=st.lists(st.lists(FIELD, min_size=1, max_size=5), max_size=40))
def test_any_csv_recording_is_read_or_refused(tmp_path: Path, monkeypatch, capsys, header,
                                              rows) -> None:
    monkeypatch.chdir(tmp_path)
    text = header + "\n" + "\n".join(",".join(r) for r in rows) + "\n"
    (tmp_path / "rec.csv").write_text(text)
    code, lines = run(["data", "show", "rec.csv"], capsys)
    if code != 0:
        refused_in_one_line(code, lines)
        assert "rec.csv" in lines[-1]


RECORD = st.fixed_dictionaries({}, optional={
    "key": st.text(max_size=4), "point": st.text(max_size=4),
    "status": st.sampled_from(["ok", "failed", "zzz"]),
    "parameters": st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
    "settings": st.just({}), "metrics": st.dictionaries(
        st.sampled_from(["rms_error_mm", "max_error_mm"]),
        st.floats(allow_nan=True) | st.text(max_size=3), max_size=2),
    "objective": st.just({"metric": "rms_error_mm"}) | st.integers()})


@PROPERTY
@given(lines=st.lists(RECORD.map(json.dumps) | st.text(max_size=30), min_size=1, max_size=8))
def test_any_results_file_is_reported_or_refused(tmp_path: Path, monkeypatch, capsys,
                                                 lines) -> None:
    monkeypatch.chdir(tmp_path)
    (tmp_path / "results.jsonl").write_text("\n".join(lines) + "\n")
    code, out = run(["tune", "report", "results.jsonl"], capsys)
    if code != 0:
        refused_in_one_line(code, out)
