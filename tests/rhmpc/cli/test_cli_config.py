"""`rhmpc config show` (TOML that --config reads back) and unknown keys listing the valid ones."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from rhmpc.cli import main
from rhmpc.cli.config import attribute_docs, summary, unit_of
from rhmpc.control.reference import ReferenceSettings
from rhmpc.experiment import RunConfig, load_config
from rhmpc.experiment.config import SECTIONS
from rhmpc.experiment.presets import PRESETS
from rhmpc.sim.loop import LoopSettings


def _show(capsys, tmp_path: Path, *argv: str) -> tuple[str, RunConfig]:
    assert main(["config", "show", *argv]) == 0
    text = capsys.readouterr().out
    path = tmp_path / "run.toml"
    path.write_text(text)
    return text, load_config(path)


def test_show_round_trips_to_the_same_settings(capsys, tmp_path: Path) -> None:
    _, config = _show(capsys, tmp_path)
    assert config == RunConfig()  # the defaults of every command
    _, config = _show(capsys, tmp_path, "--preset", "tuna2013", "--set", "predictor=ekf",
                         "--set", "sensor_settings.playback=\"hold\"", "--set",
                         "mpc.blocks=[25, 25]", "--set", "loop.poi_offset=[0.001, 0.0, 0.0]")
    expected = RunConfig().replace(**{
        **PRESETS["tuna2013"], "predictor": "ekf", "sensor_settings.playback": "hold",
        "mpc.blocks": (25, 25), "loop.poi_offset": (1e-3, 0.0, 0.0)})
    assert config == expected
    again, _ = _show(capsys, tmp_path, "--config", str(tmp_path / "run.toml"))
    assert load_config(tmp_path / "run.toml") == expected and "source: config" in again


def test_show_states_unit_default_and_source(capsys, tmp_path: Path) -> None:
    text, _ = _show(capsys, tmp_path, "--preset", "tuna2013", "--set", "mpc.rate_weight=0.3")
    lines = text.splitlines()

    def comment(key: str) -> str:
        return lines[lines.index(key) - 1]

    assert "[-] — default 0.0001, source: preset tuna2013" in comment("effort_weight = 50.0")
    assert "default 0.1, source: --set" in comment("rate_weight = 0.3")
    assert comment("Ts = 0.0005").startswith("# Control period (0.5 ms: 2 kHz in Tuna et al.")
    assert "[m/s]" in comment("guard_speed = 0.3")
    assert "[s] — default 30.0, source: default" in comment("duration = 30.0")
    assert "osqp_rho = 3.0" in lines and "[mpc.osqp]" not in lines
    assert "# joint_lower =   (unset)" in lines  # unset keys stay out, commented
    for section in SECTIONS:
        assert f"[{section}]" in lines
    assert any(line.startswith("# order = 10") for line in lines)  # generalized's own settings


def test_units_come_from_the_attributes_sections() -> None:
    docs = attribute_docs(LoopSettings)
    assert {f.name for f in dataclasses.fields(LoopSettings)} <= set(docs)
    assert unit_of(attribute_docs(ReferenceSettings)["outlier_gate"][1]) == "m"
    assert unit_of(docs["downsample"][1]) is None
    assert unit_of("R[0] = δ I [m²]; tiny") == "m²"  # an index is no unit
    assert unit_of("the step is ``Ts / substeps`` [s].") is None  # the literal's unit
    assert summary("Ticks between updates (15 → 7.5 ms, Tuna et al. Fig. 9). More.") == \
        "Ticks between updates (15 → 7.5 ms, Tuna et al. Fig. 9)"
    assert summary("One. Two.", long=True) == "One. Two."


@pytest.mark.parametrize("section", list(SECTIONS))
def test_unknown_keys_list_the_valid_ones(capsys, tmp_path: Path, section: str) -> None:
    valid = [f.name for f in dataclasses.fields(SECTIONS[section])]
    assert main(["simulate", "--set", f"{section}.nope=1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "__init__" not in err
    assert f"unknown setting(s) {section}.nope; valid keys of [{section}]: " in err
    assert err.endswith(", ".join(valid))
    path = tmp_path / "bad.toml"
    path.write_text(f"[{section}]\nnope = 1\n")
    assert main(["simulate", "--config", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "nope" in err and err.endswith(", ".join(valid)) and len(err.splitlines()) == 1


def test_unknown_sections_and_top_level_keys(capsys) -> None:
    assert main(["simulate", "--set", "foo.bar=1"]) == 2
    assert "unknown section 'foo' in foo.bar; valid sections: loop, reference, mpc" in \
        capsys.readouterr().err
    assert main(["config", "show", "--set", "nope=1"]) == 2
    assert "unknown setting(s) nope; valid: data, data_read" in capsys.readouterr().err
    assert main(["config"]) == 2
    assert "choose an action: show" in capsys.readouterr().err


def _one_line_error(capsys, argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("section", list(SECTIONS))
def test_a_section_given_a_value_names_the_section(capsys, section: str) -> None:
    """``--set loop=1``: a section is a table; ``--set loop={duration=3.0}`` sets its key."""
    for value in ("1", "true", '"x"', "[1, 2]"):
        err = _one_line_error(capsys, ["config", "show", "--set", f"{section}={value}"])
        assert f"{section} is a section of settings" in err and f"{section}.KEY=VALUE" in err


def test_a_section_given_a_table_sets_its_keys(capsys, tmp_path: Path) -> None:
    _, config = _show(capsys, tmp_path, "--set", "loop={duration = 3.0, downsample = 5}")
    assert (config.loop.duration, config.loop.downsample) == (3.0, 5)


#: A value of each kind but the one of its field: a table, a list, a boolean and a string.
OTHER_KINDS = {"a table": "{a = 1}", "a list": "[1, 2]", "a boolean": "true", "a string": '"x"'}


def _wrong_kinds(annotation: str) -> list[str]:
    """The kinds of :data:`OTHER_KINDS` a field annotated ``annotation`` does not take."""
    takes = {"a list": "tuple" in annotation, "a boolean": "bool" in annotation,
             "a string": "str" in annotation or "Any" in annotation, "a table": False}
    return [kind for kind, taken in takes.items() if not taken]


@pytest.mark.parametrize("section", list(SECTIONS))
def test_every_setting_given_the_wrong_kind_names_its_key(capsys, tmp_path: Path,
                                                         section: str) -> None:
    """Each field of each section, on the command line and in a settings file, given each kind
    of value it does not take: one line naming the key, never a traceback."""
    cls = SECTIONS[section]
    for f in dataclasses.fields(cls):
        for kind in _wrong_kinds(str(f.type)):
            value = OTHER_KINDS[kind]
            err = _one_line_error(capsys, ["config", "show", "--set",
                                           f"{section}.{f.name}={value}"])
            assert f"[{section}] {f.name} must be" in err and f"got {kind}" in err, err
        path = tmp_path / "bad.toml"
        path.write_text(f"[{section}]\n{f.name} = {{ a = 1 }}\n")
        err = _one_line_error(capsys, ["config", "show", "--config", str(path)])
        assert f"[{section}] {f.name} must be" in err and "got a table" in err, err
