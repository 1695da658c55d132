"""`--preset tuna2013`, `compare --paper`/`--seed`/`--json`, and bad sensor settings (exit 2)."""

import argparse
import json

import pytest

from rhmpc.cli import build_parser, main
from rhmpc.cli.compare import configs
from rhmpc.cli.presets import PRESETS
from rhmpc.cli.simulate import config_from_args
from rhmpc.studies.paper import COLUMNS, TUNA2013, paper_table


def _args(*argv) -> argparse.Namespace:
    return build_parser().parse_args(list(argv))


def test_preset_sets_the_effort_weight_and_set_still_wins() -> None:
    assert config_from_args(_args("simulate", "--preset", "tuna2013")).mpc.effort_weight == 50.0
    config = config_from_args(_args("simulate", "--preset", "tuna2013", "--set",
                                    "mpc.effort_weight=7"))
    assert config.mpc.effort_weight == 7.0
    runs = configs(_args("compare", "--preset", "tuna2013", "--seed", "3", "--seeds", "2",
                         "--predictors", "exact", "--scenarios", "fixed-a2-top"))
    assert [c.seed for c in runs] == [3, 4]
    assert all(c.mpc.effort_weight == PRESETS["tuna2013"]["mpc.effort_weight"] for c in runs)


def test_paper_table_has_every_cell_with_its_ratio() -> None:
    docs = [{"predictor": p, "scenario": s, "rms_error_mm": 0.1, "max_error_mm": 1.0,
             "rms_effort_mNm": 10.0} for p in ("exact", "one-step", "generalized", "ekf")
            for s in COLUMNS]
    text = paper_table(docs, ["exact", "one-step", "generalized", "ekf"], list(COLUMNS))
    cells = sum(len(rows) * len(COLUMNS) for rows in TUNA2013.values())
    assert cells == 3 * 3 * 6 + 2 * 4 * 6
    assert text.count(" / ") == 2 * cells + 2 * len(TUNA2013)  # every cell, every title
    assert "0.237 / 0.100 / 0.42" in text  # Table I, fixed-a2-top, exact RMS
    assert "5.157 / 1.000 / 0.19" in text  # Table III, fixed-a1-top, EKF max


def test_compare_json_rows(capsys) -> None:
    code = main(["compare", "--predictors", "exact,one-step", "--scenarios", "fixed-a2-top",
                 "--duration", "0.6", "--settling", "0.2", "--jobs", "1", "--json",
                 "--preset", "tuna2013"])
    rows = json.loads(capsys.readouterr().out)
    assert code == 0 and len(rows) == 2
    assert {(r["scenario"], r["predictor"]) for r in rows} == {
        ("fixed-a2-top", "exact"), ("fixed-a2-top", "one-step")}
    assert all({"rms_error_mm", "max_error_mm", "rms_effort_mNm"} <= set(r) for r in rows)


@pytest.mark.parametrize("setting, message", [
    ("sensor_settings.diameter=-0.05", "diameter must be a finite length > 0"),
    ("sensor_settings.crystals=3", "≥ 4 reference crystals"),
    ("sensor_settings.sound_speed=nan", "sound_speed must be finite"),
    ("sensor_settings.playback=\"later\"", "unknown playback"),
])
def test_bad_sensor_settings_one_line_exit_2(capsys, setting, message) -> None:
    for command in ("simulate", "compare"):
        code = main([command, "--duration", "0.5", "--set", setting])
        err = capsys.readouterr().err
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1
