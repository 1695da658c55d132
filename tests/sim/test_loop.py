"""Closed-loop invariants on short runs (real MPC, real plant, stand-in or real heart motion)."""

import dataclasses

import numpy as np
import pytest

from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.reference import ExactReference, PredictedReference
from rhmpc.control.settings import MPCSettings
from rhmpc.experiment import RunConfig, build_run, run_experiment
from robots import linearize, load_robot
from sim.loop import LoopSettings, poi_truth, run_closed_loop
from tests.sim.stand_ins import HarmonicHeart, ideal_stream

SHORT = LoopSettings(duration=3.0, settling=1.0)


@pytest.fixture(scope="module")
def phantom():
    robot = load_robot("phantom")
    return robot, linearize(robot)


def run_with(phantom, reference_of, stream_of=None, settings=SHORT, controller=None):
    robot, arm = phantom
    src = HarmonicHeart()
    center, truth = poi_truth(src, settings.ticks + settings.horizon + 1, settings.Ts)
    stream = (stream_of or (lambda s: ideal_stream(s, settings.duration + 0.1)))(src)
    mpc = controller or RecedingHorizonMPC(arm, MPCSettings())
    return run_closed_loop(robot, arm, mpc, reference_of(truth), truth, center, stream, settings)


def predicted(name, **settings):
    from predictors import make_predictor

    def build(truth):
        pred = make_predictor(name, dt=SHORT.downsample * SHORT.Ts, **settings)
        return PredictedReference(pred, SHORT.Ts, SHORT.horizon, SHORT.downsample)

    return build


def test_exact_reference_tracks_far_below_the_heart_amplitude(phantom):
    result = run_with(phantom, lambda truth: ExactReference(truth, SHORT.horizon))
    m = result.metrics()
    amplitude_mm = 1e3 * np.ptp(result.poi, axis=0).max()
    assert amplitude_mm > 5.0
    assert m["rms_error_mm"] < 0.02 * amplitude_mm  # far below the ~8 mm motion
    robot, _ = phantom
    assert np.all(np.abs(result.tau) <= robot.torque_limit + 1e-12)
    assert result.controller_stats["fallback_total"] <= 5  # at most a start-up transient


def test_no_prediction_is_much_worse_than_exact(phantom):
    exact = run_with(phantom, lambda truth: ExactReference(truth, SHORT.horizon)).metrics()
    hold = run_with(phantom, predicted("hold")).metrics()
    assert hold["rms_error_mm"] > 3 * exact["rms_error_mm"]


def test_prediction_beats_holding_the_last_sample(phantom):
    hold = run_with(phantom, predicted("hold")).metrics()
    gen = run_with(phantom, predicted("generalized")).metrics()
    assert gen["rms_error_mm"] < 0.5 * hold["rms_error_mm"]


def nan_and_spikes(source, duration=3.2):
    stream = ideal_stream(source, duration, rate=257.0)
    rng = np.random.default_rng(7)
    z = stream.z.copy()
    z[rng.random(len(z)) < 0.2] = np.nan  # 20 % dropped samples
    z[100:400] = np.nan  # a 1.2 s occlusion
    spikes = rng.random(len(z)) < 0.02
    z[spikes] += rng.normal(scale=5e-3, size=(spikes.sum(), 3))  # 5 mm echo outliers
    z[50, 1] = np.inf
    return dataclasses.replace(stream, z=z) if dataclasses.is_dataclass(stream) else \
        type(stream)(t=stream.t, z=z, arrival=stream.arrival)


@pytest.mark.parametrize("name", ["generalized", "one-step", "ekf", "hold"])
def test_nan_laden_spiky_stream_never_gives_nan_torque(phantom, name):
    result = run_with(phantom, predicted(name), stream_of=nan_and_spikes)
    robot, _ = phantom
    assert np.all(np.isfinite(result.tau_mpc)) and np.all(np.isfinite(result.tau))
    assert np.all(np.abs(result.tau) <= robot.torque_limit + 1e-12)
    assert np.all(np.isfinite(result.ee))
    assert result.predictor_counts.get("missing", 0) > 0


def spiky(source, duration=3.2):
    """257 Hz samples with 5 mm echo outliers lasting two samples (7.8 ms, so that the 7.5 ms
    predictor sees each), every 0.5 s from 1.2 s on."""
    stream = ideal_stream(source, duration, rate=257.0)
    z = stream.z.copy()
    for t_spike in np.arange(1.2, 3.0, 0.5):
        k = int(t_spike * 257.0)
        z[k:k + 2] += np.array([5e-3, 0.0, 0.0])
    return type(stream)(t=stream.t, z=z, arrival=stream.arrival)


def test_outlier_gate_keeps_the_robot_from_chasing_echo_spikes(phantom):
    """Against the true motion: with the gate the spikes leave no trace; without it the robot
    jumps towards each 5 mm spike."""
    def gated(gate):
        from predictors import make_predictor

        def build(truth):
            pred = make_predictor("generalized", dt=SHORT.downsample * SHORT.Ts)
            return PredictedReference(pred, SHORT.Ts, SHORT.horizon, SHORT.downsample,
                                      outlier_gate=gate)
        return build

    with_gate = run_with(phantom, gated(1.5e-3), stream_of=spiky)
    without = run_with(phantom, gated(0.0), stream_of=spiky)
    clean = run_with(phantom, gated(1.5e-3)).metrics()
    assert with_gate.predictor_counts["outliers_rejected"] >= 3
    assert with_gate.metrics()["max_error_mm"] < 2 * clean["max_error_mm"]
    assert without.metrics()["max_error_mm"] > 1.0 > with_gate.metrics()["max_error_mm"]


def test_scripted_solver_failures_are_survived_and_counted(phantom):
    _robot, arm = phantom
    mpc = RecedingHorizonMPC(arm, MPCSettings())
    mpc.force_failures(40)
    result = run_with(phantom, lambda truth: ExactReference(truth, SHORT.horizon), controller=mpc)
    stats = result.controller_stats
    assert stats["failures"].get("injected") == 40
    assert stats["fallback_total"] == 40
    assert np.all(np.isfinite(result.tau))
    assert result.metrics()["rms_error_mm"] < 0.5


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

    _, doc = run_experiment(small_config())
    doc = json.loads(json.dumps(doc))  # it is plain JSON
    for key, kind in DOCUMENTED_KEYS.items():
        assert isinstance(doc[key], kind), key
    assert set(doc["tick_us"]) >= {"p50", "p99", "max"}
    assert doc["settings"]["loop"]["duration"] == 1.5


def test_same_seed_same_numbers_other_seed_other_numbers():
    keys = ("rms_error_mm", "max_error_mm", "rms_effort_mNm")
    a = run_experiment(small_config(seed=3))[1]
    b = run_experiment(small_config(seed=3))[1]
    c = run_experiment(small_config(seed=4))[1]
    assert [a[k] for k in keys] == [b[k] for k in keys]
    assert [a[k] for k in keys] != [c[k] for k in keys]


def test_truth_and_stream_start_together():
    run = build_run(small_config(ground_truth="true"))
    assert run.stream.t[0] == 0.0
    assert run.truth.shape[0] == run.config.loop.ticks + run.config.loop.horizon + 1
