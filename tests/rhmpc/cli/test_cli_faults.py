"""`rhmpc simulate --fault` and the ``[faults]`` table of a run file."""

import json

import pytest

from rhmpc.cli import main
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, load_config, save_config


@pytest.mark.parametrize(("argv", "message"), [
    (["--fault", "freeze@x:0.3"], "--fault 'freeze@x:0.3': the start must be a number"),
    (["--fault", "jump@2:5"], "needs a length unit"),
    (["--fault", "melt@2:1"], "expected KIND@START"),
    (["--fault", "nan@0.9", "--duration", "1.2"], "ends at 1.4 s, after the run's 1.2 s"),
    (["--fault", "freeze@3:0.1", "--duration", "2"], "starts at 3 s, not within the run's 2 s"),
    (["--fault", "stick@0.5:0.1:5", "--duration", "1"], "joint 5 does not exist"),
])
def test_a_bad_fault_is_a_one_line_error(capsys, argv, message):
    assert main(["simulate", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err


def test_faults_from_the_command_line_reach_the_document(capsys, tmp_path):
    config = tmp_path / "run.toml"
    save_config(RunConfig().replace(**{"faults.events": ("nan@0.5:0.1",)}), config)
    code = main(["simulate", "--config", str(config), "--duration", "1.0", "--settling", "0.3",
                 "--fault", "jump@0.8:0.5,0,0mm", "--json"])
    assert code == 0
    doc = json.loads(capsys.readouterr().out)
    assert [f["fault"] for f in doc["faults"]] == ["nan@0.5:0.1", "jump@0.8:0.5,0,0mm"]
    assert doc["settings"]["faults"]["events"] == ["nan@0.5:0.1", "jump@0.8:0.5,0,0mm"]
    assert doc["faults"][0]["during"]["counts"]["missing"] > 0


def test_the_faults_table_round_trips_and_is_left_out_when_empty(tmp_path):
    path = tmp_path / "run.toml"
    config = RunConfig().replace(**{"faults.events": ["freeze@2:0.3"], "faults.after_s": 0.5})
    save_config(config, path)
    assert "[faults]" in path.read_text() and load_config(path) == config
    assert "faults" not in RunConfig().to_dict()
    with pytest.raises(UsageError, match=r"\[faults\] fault 'freeze@2'"):
        RunConfig.from_dict({"faults": {"events": ["freeze@2"]}})
    with pytest.raises(UsageError, match="after the run's 1 s"):
        RunConfig().replace(**{"loop.duration": 1.0, "faults.events": ["freeze@0.5:0.6"]})


@pytest.mark.slow
def test_a_fault_over_the_whole_run_has_its_during_record(capsys):
    """A jump from the first tick to the end of the run: its record measures the whole run."""
    assert main(["simulate", "--fault", "jump@0:5mm", "--duration", "1.0", "--settling", "0.3",
                 "--json"]) == 0
    (fault,) = json.loads(capsys.readouterr().out)["faults"]
    assert fault["after"] is None and fault["during"]["max_error_mm"] > 4.0
    assert main(["simulate", "--fault", "jump@0:5mm", "--duration", "1.0", "--settling", "0.3"
                 ]) == 0
    assert "max error —" not in capsys.readouterr().out
