"""Predictors fitted before the run: fitting, files, reproducibility, the optional PyTorch."""

from __future__ import annotations

import copy
import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rhmpc.predictors import make_predictor
from tests.predictors.helpers import feed, tracked_points

DT = 0.04
#: a tiny network of each architecture: seconds to fit, the same code paths as the presets
TINY = {
    "lstm": {"hidden": 8, "epochs": 8, "validation": 0.0},
    "st-gru": {"hidden": 8, "layers": 2, "epochs": 8, "validation": 0.0, "heads": "joint"},
    "st-tcn": {"channels": 4, "dilations": (1, 2), "epochs": 8, "validation": 0.0},
    "st-lstm": {"hidden": 8, "epochs": 8, "heads": "joint", "ensemble": 2},
}


@pytest.fixture(scope="module")
def stream() -> np.ndarray:
    return tracked_points(400, DT, seed=7, noise=20e-6)


@pytest.mark.slow
def test_ridge_fits_forecasts_and_round_trips_a_file(stream, tmp_path) -> None:
    p = make_predictor("st-ridge", DT).fit(stream[:300])
    assert p.fitted and p.model["validation_rms"].shape == (4,)
    a = feed(p, stream, 6)
    assert np.isfinite(a).all() and np.array_equal(a[:, 5], a[:, 3])  # lead 6 holds lead 4
    path = tmp_path / "st.ridge"
    p.save(path)
    q = make_predictor("st-ridge", DT, model=str(path))
    np.testing.assert_array_equal(feed(q, stream, 6), a)
    assert q.settings.model == str(path)
    truth = stream[:, 0]
    miss = np.linalg.norm(a[320:-1, 0] - truth[321:], axis=1)
    assert np.sqrt(np.mean(miss**2)) < 0.1e-3


@pytest.mark.slow
def test_fitted_predictors_refuse_what_they_cannot_do(stream, tmp_path) -> None:
    p = make_predictor("st-ridge", DT)
    with pytest.raises(RuntimeError, match="not fitted"):
        p.update(stream[0, 0])
    with pytest.raises(RuntimeError, match="not fitted"):
        p.save(tmp_path / "x")
    with pytest.raises(ValueError, match="expected \\(T, P, d\\)"):
        p.fit(np.zeros(10))
    with pytest.raises(ValueError, match="never measured"):
        p.fit(np.full((50, 4, 3), np.nan))
    with pytest.raises(ValueError, match="disagree"):
        p.fit([stream[:200], stream[:200, :2]])
    with pytest.raises(ValueError, match="too little data"):
        p.fit(stream[:20])
    p.fit(stream[:300])
    with pytest.raises(ValueError, match="fitted on 4 point"):
        p.update(stream[0, 0], stream[0, 1:3])
    p.save(tmp_path / "st.npz")
    with pytest.raises(ValueError, match="fitted at dt"):
        make_predictor("st-ridge", 0.01, model=str(tmp_path / "st.npz"))
    with pytest.raises(ValueError, match="a 'st-ridge' model, not 'ridge'"):
        make_predictor("ridge", DT, model=str(tmp_path / "st.npz"))
    with pytest.raises(ValueError, match="windows"):
        make_predictor("ridge", DT, windows=())


@pytest.mark.slow
def test_a_gap_in_the_training_data_and_in_the_stream_is_bridged(stream) -> None:
    train = stream[:300].copy()
    train[100:110, 0] = np.nan
    train[150:160, 2] = np.nan
    p = make_predictor("st-ridge", DT).fit(train)
    live = stream.copy()
    live[320:330, 0] = np.nan
    live[340:350, 1] = np.nan
    f = feed(p, live, 4)
    assert np.isfinite(f).all() and p.counts["missing"] == 10 and p.counts["others_missing"] == 10


SCRIPT = """
import importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "torch" or name.startswith("torch."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
sys.meta_path.insert(0, Block())
import predictors, rhmpc.openloop.recordings
from predictors import make_predictor
make_predictor("st-ridge", 0.04)
try:
    make_predictor("st-lstm", 0.04)
except ImportError as exc:
    print(exc)
print("torch" in sys.modules)
"""


@pytest.mark.slow
def test_predictors_import_and_run_without_pytorch() -> None:
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                         check=True).stdout.splitlines()
    assert out == ["predictor 'st-lstm' needs PyTorch: pip install \"rhmpc[learned]\"", "False"]


@pytest.mark.slow
def test_importing_predictors_does_not_import_pytorch() -> None:
    code = "import sys, predictors, rhmpc.openloop.recordings; print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"


# -- the neural predictors (PyTorch) -------------------------------------------------


def _tiny(name: str, seed: int = 0):
    pytest.importorskip("torch", reason="the neural predictors need PyTorch (rhmpc[learned])")
    return make_predictor(name, DT, seed=seed, **TINY[name])


@pytest.mark.parametrize("name", list(TINY))
@pytest.mark.slow
def test_a_network_is_reproducible_by_seed_and_round_trips_a_file(name, stream,
                                                                   tmp_path) -> None:
    a = _tiny(name).fit(stream[:300])
    b = _tiny(name).fit(stream[:300])
    c = _tiny(name, seed=1).fit(stream[:300])
    fa, fb, fc = (feed(p, stream, 4) for p in (a, b, c))
    np.testing.assert_array_equal(fa, fb)
    assert not np.array_equal(fa, fc)
    assert np.isfinite(fa).all()
    path = tmp_path / f"{name}.npz"
    a.save(path)
    d = make_predictor(name, DT, model=str(path))
    assert d.settings == dataclasses.replace(a.settings, model=str(path))
    np.testing.assert_allclose(feed(d, stream, 4), fa, rtol=0, atol=1e-12)


@pytest.mark.slow
def test_the_file_loads_without_running_code(stream, tmp_path) -> None:
    p = _tiny("lstm").fit(stream[:300])
    path = tmp_path / "lstm.npz"
    p.save(path)
    with np.load(path, allow_pickle=False) as f:  # arrays of numbers and one text only
        assert all(f[k].dtype.kind in "fiU" for k in f.files)
    with pytest.raises(ValueError, match="a 'lstm' model, not 'gru'"):
        make_predictor("gru", DT, model=str(path))


@pytest.mark.slow
def test_the_validation_estimate_and_the_online_missing_samples(stream) -> None:
    p = make_predictor("st-tcn", DT, **{**TINY["st-tcn"], "validation": 0.2})
    pytest.importorskip("torch", reason="the neural predictors need PyTorch")
    p.fit(stream[:300])
    assert p.model["validation_rms"].shape == (4,)
    live = stream.copy()
    live[320:325, 0] = np.nan
    live[330:335, 3] = np.nan
    f = feed(p, live, 4)
    assert np.isfinite(f).all() and p.counts["missing"] == 5


@pytest.mark.parametrize("name", ["st-lstm", "st-tcn"])
def test_a_network_never_reads_the_future(name, stream) -> None:
    from tests.predictors.test_multipoint import _leak_check

    p = _tiny(name).fit(stream[:250])
    _leak_check(lambda: copy.deepcopy(p), stream, 300)


TIMING = """
import sys, time
import numpy as np
from predictors import make_predictor
from tests.predictors.helpers import feed, tracked_points
stream = tracked_points(200, 0.04, seed=7)
p = make_predictor(sys.argv[1], 0.04, params=sys.argv[2], epochs=1, validation=0.0)
p.fit(stream[:80])
feed(p, stream[:60], 4)
spent = []
for n in range(60, 200):
    tic = time.perf_counter()
    p.update(stream[n, 0], stream[n, 1:])
    p.predict(4)
    spent.append(time.perf_counter() - tic)
print(np.median(spent))
"""


@pytest.mark.slow
@pytest.mark.parametrize(("name", "params"), [("st-lstm", "xu2026"), ("st-gru", "li2022"),
                                               ("st-tcn", "xu2026"), ("st-lstm", "zhang2022")])
def test_the_presets_update_and_forecast_within_a_video_frame(name, params) -> None:
    """The literature's sizes on one core (one BLAS thread): the median update with its 4-lead
    forecast takes less than a frame of 25 frames/s, 40 ms."""
    pytest.importorskip("torch", reason="the neural predictors need PyTorch")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-c", TIMING, name, params], capture_output=True,
                         text=True, check=True, env=env, cwd=Path(__file__).parents[2])
    spent = float(out.stdout.strip())
    assert spent < 0.040, f"{1e3 * spent:.1f} ms per update"


@pytest.mark.parametrize("name", ["st-tcn", "st-gru", "lstm"])
@pytest.mark.slow
def test_the_online_steps_are_the_trained_network(name, stream) -> None:
    """One sample at a time (a recurrent network's state carried, a TCN over its span) = the
    network over the whole sequence."""
    p = _tiny(name).fit(stream[:300])
    f = feed(p, stream, 4)
    mean, std = p.model["mean"], p.model["std"]
    rows = stream[:, : p.model["points"]].reshape(stream.shape[0], -1)
    out = p._outputs(p.model["nets"], (rows - mean) / std).reshape(-1, 4, 3)
    ref = mean[:3] + std[:3] * out
    w = p._warmup()
    np.testing.assert_allclose(f[w:], ref[w:], rtol=0, atol=1e-8)
