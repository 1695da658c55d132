"""The one ``[plant]`` table in a run's settings: the keys of earlier versions are refused with
the new key, and the default and the hardware preset integrate as they did."""

import numpy as np
import pytest

from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig
from rhmpc.experiment.config import load_config, run_config
from rhmpc.experiment.run import run_experiment


@pytest.mark.parametrize("table, new", [
    ({"hardware": {"dac_bits": 16}}, "write plant.dac_bits"),
    ({"hardware": {}}, "[hardware] is now part of [plant]"),
    ({"plant": {"model": "hardware"}}, "plant.model is now plant.kind"),
    ({"plant": {"stiction_velocity": 1e-3}}, "is now plant.friction_smoothing"),
])
def test_a_key_of_an_earlier_version_is_one_line_naming_the_new_one(tmp_path, table, new):
    with pytest.raises(UsageError) as err:
        RunConfig.from_dict(table, where="run.toml")
    assert new in str(err.value) and "\n" not in str(err.value)
    assert str(err.value).startswith("run.toml: ")
    section, values = next(iter(table.items()))
    with pytest.raises(UsageError, match="is now"):
        RunConfig().replace(**{f"{section}.{k}": v for k, v in values.items()} or
                            {section: values})
    path = tmp_path / "run.toml"
    path.write_text(f"[{section}]\n" + "".join(f"{k} = {v!r}\n".replace("'", '"')
                                               for k, v in values.items()))
    with pytest.raises(UsageError, match=str(path)):
        load_config(path)


#: RMS error [mm], RMS effort [mN·m], the torques' sum over the ticks and the last tick's
#: torques [N·m] of 0.6-s runs (the generalized predictor, 0.3 s of settling) of the default
#: and the hardware presets, as the two sets of integration constants gave them before
#: ``[plant]`` held them once (``plant.model = "ideal"``, ``"hardware"``).
BEFORE = {
    (None, ()): ([0.5756374572220199, 460.93812309367496],
                 [-0.8874427234889388, 13.318659697625181, -0.03158988716031244],
                 [0.07924846682116284, -0.07057096266953217, -0.00813453653664977]),
    ("hardware", ()): ([0.7379631677484182, 715.1476132379256],
                       [-0.6619037434561804, 20.1146117470333, -0.5888885097438541],
                       [0.07614414918177927, -0.025579035833735032, -0.061862836185174935]),
    ("tuna2013-hardware", ()): (
        [1.0308657706116084, 79.08515154890016],
        [-2.257109823477907, 13.883115308641047, 0.40247307622205536],
        [-0.02244270471924077, 0.050159687901552404, -0.004049523381081145]),
    ("tuna2013-hardware", ("plant.cable_resonance=80.0", "plant.substeps=20")): (
        [102.44251923048876, 1928.8130370637175],
        [-22.531814698405647, 25.904662581354167, -29.313840885065357],
        [0.307738227136607, -1.0613230130521918, -0.13984600354386517]),
}


@pytest.mark.slow
@pytest.mark.parametrize("preset, sets", list(BEFORE))
def test_the_presets_integrate_as_before(preset, sets):
    config = run_config(preset=preset, sets=sets, options={
        "loop.duration": 0.6, "loop.settling": 0.3, "predictor": "generalized"})
    result, doc = run_experiment(config)
    rms, total, last = BEFORE[(preset, sets)]
    # another processor's rounding (numpy's and the BLAS's vector paths) moves these by up to
    # 1e-10 relative over the 1 200 ticks; other integration constants move them by far more
    np.testing.assert_allclose([doc["rms_error_mm"], doc["rms_effort_mNm"]], rms, rtol=1e-8)
    np.testing.assert_allclose(result.tau.sum(axis=0), total, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(result.tau[-1], last, rtol=1e-8, atol=1e-9)
