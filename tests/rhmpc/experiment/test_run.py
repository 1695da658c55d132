"""A configured run end to end: its document, its seeds, its streams against whole arrays."""

import dataclasses
import math

import numpy as np
import pytest

from rhmpc.control.reference import PredictedReference
from rhmpc.experiment import RunConfig, build_run, run_experiment
from rhmpc.experiment.assembly import build_controller
from rhmpc.predictors import PREDICTORS, Predictor
from rhmpc.sim.loop import LoopSettings, run_closed_loop
from rhmpc.sim.loop.closed_loop import poi_truth
from rhmpc.sim.loop.exact import ArrayTruth, ExactReference
from rhmpc.sim.plant import make_plant
from rhmpc.sim.sources import heart_source

DOCUMENTED_KEYS = {
    "rms_error_mm": float, "max_error_mm": float, "rms_effort_mNm": float, "tick_us": dict,
    "fallbacks": int, "predictor": str, "scenario": str, "robot": str, "seed": int,
    "settings": dict, "versions": dict, "prediction_rms_mm": dict, "wall_s": float,
}


def small_config(**changes):
    base = RunConfig(loop=LoopSettings(duration=1.5, settling=0.5))
    return base.replace(**changes)


def test_result_document_has_the_documented_keys():
    import json

    _, doc = run_experiment(small_config(), gain_tick=True)
    doc = json.loads(json.dumps(doc))  # it is plain JSON
    for key, kind in DOCUMENTED_KEYS.items():
        assert isinstance(doc[key], kind), key
    assert set(doc["tick_us"]) >= {"p50", "p99", "p999", "max"}
    assert doc["peak_rss_mb"] > 0 and doc["gain_tick_us"]["p50"] > 0
    assert doc["tick_ratio_to_gain"]["p99"] == doc["tick_us"]["p99"] / doc["gain_tick_us"]["p50"]
    assert doc["settings"]["loop"]["duration"] == 1.5
    # the tick without the refresh slices is part of the tick; the ticks' work per second
    control, tick, g = doc["control_tick_us"], doc["tick_us"], doc["gain_tick_us"]["p50"]
    assert 0 < control["p50"] <= tick["max"] and control["max"] <= tick["max"]
    assert doc["control_tick_ratio_to_gain"]["p99"] == control["p99"] / g
    assert math.isclose(doc["tick_per_simulated_s_g"], tick["mean"] / 0.5e-3 / g, rel_tol=1e-12)
    assert doc["tick_per_simulated_s_g"] < doc["wall_per_simulated_s_g"]


@pytest.mark.slow
def test_same_seed_same_numbers_other_seed_other_numbers():
    keys = ("rms_error_mm", "max_error_mm", "rms_effort_mNm")
    a = run_experiment(small_config(seed=3))[1]
    b = run_experiment(small_config(seed=3))[1]
    c = run_experiment(small_config(seed=4))[1]
    assert [a[k] for k in keys] == [b[k] for k in keys]
    assert [a[k] for k in keys] != [c[k] for k in keys]


def test_truth_and_stream_start_together():
    run = build_run(small_config(ground_truth="true"))
    assert run.stream.block(0, 1)[0][0] == 0.0
    assert run.truth.n_ticks == run.config.loop.ticks + run.config.mpc.horizon + 1


@pytest.mark.parametrize("predictor", ["generalized", "exact"])
@pytest.mark.slow
def test_streamed_run_is_the_run_on_whole_arrays(tmp_path, predictor):
    """The streamed run (sensor stream made block by block, truth read per window, running
    statistics over many chunks) against the same run fed whole-run arrays
    (``sensor.measure`` over the run, ``poi_truth`` of the raw recording), scored
    with the whole-array ``tracking_metrics``: equal to 1e-9 relative (measured ≤ 3e-13: sums in
    another order, the mean summed per block)."""
    from rhmpc.predictors import make_predictor
    from rhmpc.sim.loop.trace import read_trace
    from rhmpc.sim.recordings import RecordedMotion
    from rhmpc.sim.sensors import sensor_from_name
    from tests.sim.loop.test_streams import tracking_metrics

    config = small_config(predictor=predictor, seed=5, **{
        "loop.duration": 4.0, "loop.settling": 1.0})
    loop, run, N = config.loop, build_run(config), config.mpc.horizon
    streamed = run_closed_loop(  # chunks of 600 ticks: 14 chunk boundaries
        run.plant, run.controller, run.truth, run.stream, loop, run.clock, anchor=run.anchor,
        robot=run.robot, trace_file=str(tmp_path / "run.npz"), chunk_ticks=600)
    doc = streamed.metrics()

    run = build_run(config)
    heart_rng, sensor_rng = np.random.default_rng(config.seed).spawn(2)
    heart = heart_source(config.scenario, heart_rng)
    source, origin = heart.motion, heart.origin
    sensor = sensor_from_name("sonomicrometry", dim=source.dim, rate=origin.sensor_rate,
                              upsample=1.0 / loop.Ts)
    span = loop.duration + (N + 1) * loop.Ts
    stream = sensor.measure(source, span, sensor_rng)
    # the target: the recording (the raw samples, before the delivery to 2 kHz), same draws
    raw = dataclasses.replace(sensor, stages=sensor.stages[:-1]).measure(
        source, span, np.random.default_rng(config.seed).spawn(2)[1])
    target = RecordedMotion(raw.t, raw.z)
    center, truth = poi_truth(target, loop.ticks + N + 1, loop.Ts)
    if predictor == "exact":
        reference = ExactReference(truth, N)
    else:
        dt = loop.downsample * loop.Ts
        reference = PredictedReference(
            make_predictor(predictor, dt=dt, unit=1.0),  # metres, as the loop says
            loop.Ts, N, loop.downsample, config.reference)
    reference.place(run.anchor, center)
    controller = build_controller(config, run.robot, run.arm, reference)
    whole = run_closed_loop(make_plant(run.robot, run.arm, loop.Ts, config.plant), controller,
                            ArrayTruth(truth, center), stream, loop, run.clock,
                            anchor=run.anchor, robot=run.robot)
    for key in ("rms_error_mm", "max_error_mm", "rms_effort_mNm"):
        np.testing.assert_allclose(doc[key], whole.metrics()[key], rtol=1e-9, err_msg=key)
    # every tick on disk, scored on whole arrays, gives the running statistics
    trace, s = read_trace(tmp_path / "run.npz"), loop.settling_ticks
    assert trace["tick"].size == loop.ticks
    np.testing.assert_allclose(trace["ee"], whole.ee, rtol=0, atol=1e-15)
    direct = tracking_metrics(trace["ee"][s:] - trace["poi"][s:], trace["tau_mpc"][s:],
                              trace["tau"][s:])
    for key, value in direct.items():
        np.testing.assert_allclose(streamed.tracking[key], value, rtol=1e-12, err_msg=key)
    assert doc["tick_us"]["p999"] >= doc["tick_us"]["p99"] >= doc["tick_us"]["p50"] > 0


@pytest.mark.slow
def test_predictor_params_pick_each_predictors_named_set():
    """``predictor_params`` names a parameter set per predictor (a preset's choice for every
    predictor a comparison runs); ``predictor_settings.params`` still wins over it. The loop
    feeds metres and says so (``unit=1``)."""
    from rhmpc.predictors.fourier_settings import EKF_PARAMETER_SETS

    def named(name):
        return dataclasses.replace(EKF_PARAMETER_SETS[name], unit=1.0)

    params = {"ekf": "tuna2013"}
    ekf = build_run(small_config(predictor="ekf", predictor_params=params)).reference.predictor
    assert ekf.settings == named("tuna2013")
    default = build_run(small_config(predictor="ekf")).reference.predictor
    assert default.settings == named("adaptive") != named("tuna2013")
    chosen = build_run(small_config(predictor="ekf", predictor_params=params,
                                    predictor_settings={"params": "yuen2008"}))
    assert chosen.reference.predictor.settings == named("yuen2008")
    mm = build_run(small_config(predictor="ekf", predictor_settings={"unit": 1e-3}))
    assert mm.reference.predictor.settings.unit == 1e-3  # a unit the user sets is kept
    other = build_run(small_config(predictor="one-step", predictor_params=params))
    assert type(other.reference.predictor).__name__ == "OneStepRLS"


def _rms_with_shifted_forecasts(monkeypatch, predictor: str, shift: float) -> float:
    """RMS error of a short run whose predictor's forecasts are all moved by ``shift`` [m]."""
    original = Predictor.predict

    def shifted(self, steps):
        return original(self, steps) + shift

    monkeypatch.setattr(Predictor, "predict", shifted)
    config = small_config(predictor=predictor, seed=1, predictor_settings=_QUICK.get(predictor, {}),
                          **{"loop.duration": 1.2, "loop.settling": 0.6})
    return run_experiment(config)[1]["rms_error_mm"]


#: A combination of members that fit in a moment (its default members include networks, whose
#: fits on the settling window take minutes and test nothing more here).
_QUICK = {"combination": {"members": ["one-step", "st-rls", "st-ridge"]}}


def _patched_run_changes(monkeypatch, predictor: str) -> None:
    """The Python predictor is what runs: 1 mm added to every forecast moves the tool by
    about 1 mm (the RMS by far more than 0.3 mm)."""
    plain = _rms_with_shifted_forecasts(monkeypatch, predictor, 0.0)
    shifted = _rms_with_shifted_forecasts(monkeypatch, predictor, 1e-3)
    assert abs(shifted - plain) >= 0.3, (plain, shifted)


@pytest.mark.parametrize("predictor", ["generalized", "one-step"])
@pytest.mark.slow
def test_a_patched_forecast_changes_the_closed_loop_run(monkeypatch, predictor):
    _patched_run_changes(monkeypatch, predictor)


@pytest.mark.slow
@pytest.mark.parametrize("predictor", sorted(set(PREDICTORS) - {"exact", "generalized",
                                                               "one-step"}))
def test_every_predictors_patched_forecast_changes_the_run(monkeypatch, predictor):
    _patched_run_changes(monkeypatch, predictor)
