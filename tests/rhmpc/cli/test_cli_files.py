"""Files through the command line: saved models unique per input and loaded by a run, outputs
that are inputs refused before any work."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.predictors.registry import load_model
from tests.rhmpc.cli.test_cli_your_recordings import write_csv


@pytest.fixture(scope="module")
def twins(tmp_path_factory) -> list[Path]:
    """Two recordings whose names give the same plain file name: 'x y.csv' and 'x-y.csv'."""
    folder = tmp_path_factory.mktemp("twins")
    return [write_csv(folder / name, 25.0, 24.0) for name in ("x y.csv", "x-y.csv")]


@pytest.mark.slow
def test_saved_models_stay_unique_per_input_and_run_in_a_loop(twins: list[Path], tmp_path: Path,
                                                              capsys) -> None:
    models = tmp_path / "m"
    argv = ["predict", "--data", *map(str, twins), "--split", "300:400", "--predictors",
            "ridge,hold", "--save-models", str(models), "--json"]
    assert main(argv) == 0
    capsys.readouterr()
    saved = sorted(models.iterdir())
    assert len(saved) == 2 and len({p.name for p in saved}) == 2
    assert {load_model(p, "ridge").dt for p in saved} == {0.04}
    out = tmp_path / "run.json"
    code = main(["simulate", "--data", str(twins[1]), "--predictor", "ridge", "--duration", "4",
                 "--settling", "1", "--set", f'predictor_settings.model="{saved[0]}"',
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert doc["predictor"] == "ridge" and np.isfinite(doc["rms_error_mm"])


@pytest.mark.parametrize("argv", [
    ["predict", "--data", "{rec}", "--out", "{rec}"],
    ["predict", "--data", "{rec}", "--plot", "{rec}"],
    ["simulate", "--data", "{rec}", "--duration", "2", "--trace", "{npz}",
     "--train", "{npz}"],
])
def test_an_output_that_is_an_input_is_refused_first(twins: list[Path], tmp_path: Path, capsys,
                                                     argv: list[str]) -> None:
    npz = tmp_path / "t.npz"
    npz.write_bytes(b"mine")
    before = twins[0].read_bytes()
    code = main([a.format(rec=twins[0], npz=npz) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "is an input of this run" in err[-1], err
    assert twins[0].read_bytes() == before and npz.read_bytes() == b"mine"
