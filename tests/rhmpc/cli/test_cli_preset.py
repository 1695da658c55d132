"""The presets, `compare --paper`/`--seed`/`--json`, and bad sensor settings (exit 2)."""

import argparse
import json

import pytest

from rhmpc.cli import build_parser, main
from rhmpc.cli.compare import jobs
from rhmpc.cli.simulate import config_from_args
from rhmpc.experiment.presets import PRESETS
from rhmpc.paper.tables import COLUMNS, TUNA2013, paper_table


def _args(*argv) -> argparse.Namespace:
    return build_parser().parse_args(list(argv))


def test_presets_set_the_plant_and_the_weights() -> None:
    table1 = config_from_args(_args("simulate", "--preset", "tuna2013"))
    assert table1.mpc.effort_weight == 50.0 and table1.plant.kind == "linear"
    table2 = config_from_args(_args("simulate", "--preset", "tuna2013-hardware"))
    assert table2.mpc.effort_weight == 50.0 and table2.plant.label == "hardware"
    assert table2.plant.error_from == "encoders"
    assert table2.mismatch.parameters == "phantom-cavusoglu"
    hardware = config_from_args(_args("simulate", "--preset", "hardware"))
    assert hardware.plant.label == "hardware" and hardware.plant.error_from == "true"
    assert config_from_args(_args("simulate")).plant.label == "ideal"


def test_preset_sets_the_effort_weight_and_set_still_wins() -> None:
    config = config_from_args(_args("simulate", "--preset", "tuna2013", "--set",
                                    "mpc.effort_weight=7"))
    assert config.mpc.effort_weight == 7.0
    runs = [job.config for job in jobs(_args(
        "compare", "--preset", "tuna2013", "--seed", "3", "--seeds", "2", "--predictors",
        "exact", "--scenarios", "fixed-a2-top"))]
    assert [c.seed for c in runs] == [3, 4]
    assert all(c.mpc.effort_weight == PRESETS["tuna2013"]["mpc.effort_weight"] for c in runs)


#: A run's ``[plant]`` table of each plant.
PLANT_TABLES = {"linear": {"kind": "linear"}, "ideal": {}, "hardware": {"delay_ticks": 1}}


def _docs(plant: str, **scale) -> list[dict]:
    """Synthetic results: RMS 0.1 mm × the predictor's scale, effort 10 mN·m × the same."""
    return [{"predictor": p, "scenario": s, "seed": 0, "rms_error_mm": 0.1 * scale.get(p, 1.0),
             "max_error_mm": 1.0, "rms_effort_mNm": 10.0 * scale.get(p, 1.0),
             "prediction_rms_mm": {"lead_N": 0.2}, "settings": {"plant": PLANT_TABLES[plant]}}
            for p in ("exact", "one-step", "generalized", "ekf") for s in COLUMNS]


def test_paper_table_has_every_cell_of_its_setting_only() -> None:
    """Simulation runs beside Table I only, hardware runs beside Tables II–III only; every
    cell as paper / ours / ratio."""
    preds = ["exact", "one-step", "generalized", "ekf"]
    sim = paper_table(_docs("linear"), preds, list(COLUMNS))
    hw = paper_table(_docs("hardware"), preds, list(COLUMNS))
    per_table = {t: sum(len(rows) * len(COLUMNS) for (tt, _), rows in TUNA2013.items() if tt == t)
                 for t in ("I", "II", "III")}
    assert per_table == {"I": 54, "II": 54, "III": 12}
    tables = {k: text.split("Published")[0] for k, text in (("sim", sim), ("hw", hw))}
    # every cell, every title and the header line that says what a cell holds
    assert tables["sim"].count(" / ") == 2 * per_table["I"] + 2 * 3 + 2
    assert tables["hw"].count(" / ") == 2 * (per_table["II"] + per_table["III"]) + 2 * 5 + 2
    assert "Table II" not in tables["sim"] and "Table I " not in tables["hw"]
    assert "EKF" not in sim.split("Published")[1]  # Table I has no EKF row: no finding
    assert "0.237 / 0.100 / 0.42" in sim  # Table I, fixed-a2-top, exact RMS
    assert "5.157 / 1.000 / 0.19" in hw  # Table III, fixed-a1-top, EKF max
    assert "28.512 / 10.000 / 0.35" in hw  # Table II(b), fixed-a2-top, exact effort
    assert "plant.kind = \"linear\" is" in paper_table(_docs("ideal"), preds, list(COLUMNS))


@pytest.mark.slow
def test_compare_json_rows(capsys) -> None:
    code = main(["compare", "--predictors", "exact,one-step", "--scenarios", "fixed-a2-top",
                 "--duration", "0.6", "--settling", "0.2", "--jobs", "1", "--json",
                 "--preset", "tuna2013"])
    rows = json.loads(capsys.readouterr().out)["runs"]
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


@pytest.mark.parametrize("setting, message", [
    ("plant.kind=\"rigid\"", "unknown plant kind 'rigid'"),
    ("plant.dac_bits=-1", "plant dac_bits must be an integer >= 0"),
    ("plant.error_from=\"tip\"", "plant error_from must be one of true, encoders"),
    ("plant.dac_bits=16", "plant dac_bits needs a current drive"),
    ("plant.model=\"hardware\"", "plant.model is now plant.kind"),
    ("plant.stiction_velocity=0.001", "plant.stiction_velocity is now plant.friction_smoothing"),
    ("hardware.dac_bits=16", "[hardware] is now part of [plant]: write plant.dac_bits"),
    ("mismatch.parameters=\"puma\"", "unknown parameters 'puma'"),
])
def test_bad_plant_settings_one_line_exit_2(capsys, setting, message) -> None:
    code = main(["simulate", "--duration", "0.5", "--set", setting])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
