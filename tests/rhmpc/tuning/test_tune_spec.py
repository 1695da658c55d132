"""`rhmpc tune` specs: parsing, errors naming the key, sampling, evaluation keys."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig
from rhmpc.tuning.evaluate import evaluation_key
from rhmpc.tuning.spec import load_spec, parse_spec

EXAMPLES = Path(__file__).resolve().parents[3] / "examples" / "tune"

TINY = """
name = "tiny"
[base]
predictor = "generalized"
[base.loop]
duration = 0.6
settling = 0.2
[parameters]
"mpc.effort_weight" = [1e-4, 1e-3]
[evaluate]
scenarios = ["fixed-a2-top"]
"""


def spec_from(text: str):
    return parse_spec(tomllib.loads(text), where="spec.toml")


def test_tiny_spec_tasks() -> None:
    spec = spec_from(TINY)
    tasks = spec.tasks()
    assert [t.parameters for t in tasks] == [{"mpc.effort_weight": 1e-4},
                                            {"mpc.effort_weight": 1e-3}]
    assert len({t.key for t in tasks}) == 2
    config = tasks[1].config
    assert config.mpc.effort_weight == 1e-3 and config.loop.duration == 0.6
    assert config.scenario == "fixed-a2-top" and config.seed == 0


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.toml")), ids=lambda p: p.name)
def test_examples_parse(path: Path) -> None:
    spec = load_spec(path)
    assert spec.tasks()


@pytest.mark.parametrize(
    ("text", "named"),
    [
        ("[parameterz]\n", "'parameterz'"),
        ('[parameters]\n"mpc.effort_wieght" = [1.0]\n', "parameters.mpc.effort_wieght"),
        ('[parameters]\n"mpc.effort_weight" = [-1.0]\n', "parameters.mpc.effort_weight"),
        ('[parameters]\n"mpc.effort_weight" = []\n', "parameters.mpc.effort_weight"),
        ('[parameters]\n"mpc.effort_weight" = 3\n', "parameters.mpc.effort_weight"),
        ('[parameters]\n"mpc.effort_weight" = {low = 1e-5, high = 1e-3}\n',
         "parameters.mpc.effort_weight"),
        ('[parameters]\n"mpc.effort_weight" = {low = 1e-3, high = 1e-5}\n'
         '[sampler]\nmethod = "lhs"\nbudget = 3\n', "parameters.mpc.effort_weight"),
        ('[parameters]\n"mpc.effort_weight" = {low = 1e-5, high = 1e-3, step = 2}\n'
         '[sampler]\nmethod = "lhs"\nbudget = 3\n', "parameters.mpc.effort_weight.step"),
        ('[parameters.predictor_settings]\nordr = [4, 8]\n', "ordr"),
        ('[parameters]\n"loop.downsample" = [0]\n', "parameters.loop.downsample"),
        ('[parameters]\n"mpc.effort_weight" = [1.0]\n[sampler]\nmethod = "lhs"\n',
         "sampler.budget"),
        ('[parameters]\n"mpc.effort_weight" = [1.0]\n[sampler]\nmethod = "sobol"\n',
         "sampler.method"),
        ('[parameters]\n"mpc.effort_weight" = [1.0]\n[evaluate]\nscenarios = ["nope"]\n',
         "evaluate.scenarios"),
        ('[parameters]\n"mpc.effort_weight" = [1.0]\n[evaluate]\nseeds = 0\n',
         "evaluate.seeds"),
        ('[parameters]\n"mpc.effort_weight" = [1.0]\n[objective]\npenalty = {metric = '
         '"rms_effort_mNm"}\n', "objective.penalty.weight"),
        ('[parameters]\n"mpc.effort_weight" = [1.0]\n[objective]\ngoal = "max"\n',
         "objective.goal"),
        ('base = "missing.toml"\n[parameters]\n"mpc.effort_weight" = [1.0]\n', "base"),
        ('[base]\nrobbot = "phantom"\n[parameters]\n"mpc.effort_weight" = [1.0]\n', "robbot"),
        ('[base.mpc]\nrate_weight = -1.0\n[parameters]\n"mpc.effort_weight" = [1.0]\n',
         "rate_weight"),
        ("[parameters]\n", "parameters"),
        ('[parameters]\nseed = [1, 2]\n', "evaluate.seeds"),
    ],
)
def test_malformed_spec_names_the_key(text: str, named: str) -> None:
    with pytest.raises(UsageError) as info:
        spec_from(text)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith("spec.toml")
    assert named in message, message


def test_cli_malformed_spec_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = tmp_path / "bad.toml"
    spec.write_text('[parameters]\n"mpc.effort_wieght" = [1.0]\n')
    assert main(["tune", str(spec), "--results", str(tmp_path / "r.jsonl")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "parameters.mpc.effort_wieght" in err and str(spec) in err
    assert not (tmp_path / "r.jsonl").exists()


def test_cli_mode_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tune", "report", str(tmp_path / "r.jsonl"), "--jobs", "2"]) == 2
    assert "--jobs does not apply to report" in capsys.readouterr().err
    assert main(["tune", "report", str(tmp_path / "missing.jsonl")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_base_from_config_file(tmp_path: Path) -> None:
    (tmp_path / "run.toml").write_text('predictor = "one-step"\n[loop]\nduration = 6.0\n')
    spec = spec_from(f'base = "{tmp_path / "run.toml"}"\n[parameters]\n'
                     '"predictor_settings.order" = [8, 16]\n')
    configs = [t.config for t in spec.tasks()]
    assert [c.predictor_settings["order"] for c in configs] == [8, 16]
    assert all(c.predictor == "one-step" and c.loop.duration == 6.0 for c in configs)
    # relative to the spec's folder
    (tmp_path / "spec.toml").write_text('base = "run.toml"\n[parameters]\n'
                                        '"predictor_settings.order" = [8]\n')
    assert load_spec(tmp_path / "spec.toml").base.predictor == "one-step"


def test_nested_and_dotted_parameters_agree() -> None:
    a = spec_from('[parameters.mpc]\neffort_weight = [1e-4]\nrate_weight = [0.1, 1.0]\n')
    b = spec_from('[parameters]\n"mpc.effort_weight" = [1e-4]\n"mpc.rate_weight" = [0.1, 1.0]\n')
    assert [t.key for t in a.tasks()] == [t.key for t in b.tasks()]


def test_grid_range_with_num_and_log_scale() -> None:
    spec = spec_from('[parameters]\n"mpc.effort_weight" = {low = 1e-5, high = 1e-3, '
                     'scale = "log", num = 3}\n"loop.downsample" = {low = 5, high = 15, num = 3}\n')
    values = [(t.parameters["mpc.effort_weight"], t.parameters["loop.downsample"])
              for t in spec.tasks()]
    assert len(values) == 9
    assert sorted({v[0] for v in values}) == pytest.approx([1e-5, 1e-4, 1e-3])
    assert sorted({v[1] for v in values}) == [5, 10, 15]
    assert all(isinstance(v[1], int) for v in values)


def test_lhs_one_sample_per_stratum_and_seeded() -> None:
    text = ('[parameters]\n"mpc.effort_weight" = {low = 0.0, high = 1.0}\n'
            '"mpc.rate_weight" = {low = 1e-3, high = 1.0, scale = "log"}\n'
            '[sampler]\nmethod = "lhs"\nbudget = 8\nseed = 3\n')
    points = spec_from(text).points()
    assert points == spec_from(text).points()  # deterministic: a re-run resumes
    x = np.array([p["mpc.effort_weight"] for p in points])
    y = np.log10([p["mpc.rate_weight"] for p in points])
    assert sorted(np.floor(x * 8).astype(int)) == list(range(8))
    assert sorted(np.floor((y + 3) / 3 * 8).astype(int)) == list(range(8))
    other = spec_from(text.replace("seed = 3", "seed = 4")).points()
    assert other != points


def test_random_sampler_choices_and_integers() -> None:
    spec = spec_from('[parameters]\n"predictor" = ["one-step", "generalized"]\n'
                     '"predictor_settings.order" = {low = 4, high = 12}\n'
                     '[sampler]\nmethod = "random"\nbudget = 20\n')
    points = spec.points()
    assert len(points) == 20
    assert {p["predictor"] for p in points} == {"one-step", "generalized"}
    assert all(isinstance(p["predictor_settings.order"], int)
               and 4 <= p["predictor_settings.order"] <= 12 for p in points)


def test_include_base_dedupes_and_flags() -> None:
    spec = spec_from('[parameters]\n"mpc.effort_weight" = [1e-4, 1e-3]\n'
                     '[sampler]\ninclude_base = true\n[evaluate]\nseeds = 2\n')
    tasks = spec.tasks()
    assert len(tasks) == 4  # the default 1e-4 is on the grid: not evaluated twice
    assert [t.base for t in tasks] == [True, True, False, False]
    assert [t.settings["seed"] for t in tasks] == [0, 1, 0, 1]


def test_key_ignores_implicit_vs_explicit_defaults() -> None:
    base = RunConfig(predictor="one-step")
    explicit = base.replace(**{"predictor_settings.order": 16})
    assert evaluation_key(base) == evaluation_key(explicit)
    assert evaluation_key(base) != evaluation_key(base.replace(seed=1))
    assert evaluation_key(base, point=True) == evaluation_key(base.replace(seed=1), point=True)
    assert evaluation_key(base) != evaluation_key(base.replace(**{"predictor_settings.order": 8}))


def test_metric_names_and_values() -> None:
    from rhmpc.tuning.objective import check_objective_metrics, metric_value

    metrics = {"rms_error_mm": 0.3, "tick_us": {"p99": 80.0}, "rms_error_axis_mm": [0.1, 0.2]}
    assert metric_value(metrics, "tick_us.p99") == 80.0
    assert metric_value(metrics, "rms_error_axis_mm.1") == 0.2
    assert np.isnan(metric_value(metrics, "tick_us.p50"))
    spec = spec_from('[parameters]\n"mpc.effort_weight" = [1.0]\n[objective]\n'
                     'metric = "tick_us.p99"\n')
    check_objective_metrics(spec.objective, metrics)
    spec = spec_from('[parameters]\n"mpc.effort_weight" = [1.0]\n[objective]\n'
                     'constraint = {metric = "rms_efort_mNm", max = 1.0}\n')
    with pytest.raises(UsageError, match="'rms_efort_mNm' is not in the results"):
        check_objective_metrics(spec.objective, metrics)


def test_cli_seed_and_dry_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = tmp_path / "lhs.toml"
    spec.write_text('[parameters]\n"mpc.rate_weight" = {low = 0.01, high = 1.0, scale = "log"}\n'
                    '[sampler]\nmethod = "lhs"\nbudget = 4\n')
    tables = []
    for seed in ("1", "1", "2"):
        assert main(["tune", str(spec), "--seed", seed, "--dry-run",
                     "--results", str(tmp_path / "r.jsonl")]) == 0
        captured = capsys.readouterr()
        assert "4 points × 1 evaluations = 4; done 0, failed 0, to run 4" in captured.err
        tables.append(captured.out)
    assert tables[0] == tables[1] != tables[2]
    assert not (tmp_path / "r.jsonl").exists()
