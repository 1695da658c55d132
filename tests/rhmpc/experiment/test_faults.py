"""Each fault alone in a short closed loop: the run goes on, the truth is the clean run's, the
joint envelope holds, and the report counts what happened (rhmpc.sim.loop.faults)."""

import numpy as np
import pytest

from rhmpc.experiment import RunConfig, build_run, run_experiment
from rhmpc.report.summary import format_summary

#: 3 s on the ideal 2-kHz sensor (a refresh every 15 ticks reads the sample of its own tick),
#: the outlier gate calibrated by 1 s; every fault starts at 1.5 s.
BASE = RunConfig(sensor="ideal").replace(**{"loop.duration": 3.0, "loop.settling": 1.0,
                                            "reference.gate_calibration": 0.5})
START = 1.5


def run(*events):
    return run_experiment(BASE.replace(**{"faults.events": events}))


@pytest.fixture(scope="module")
def clean():
    return run()


def samples_in(result, t0, t1):
    """(stamps, z) of the refreshes' samples stamped in [t0, t1) (every one: a short run)."""
    stamps, z = result.samples
    inside = (stamps >= t0 - 1e-12) & (stamps < t1 - 1e-12)
    return stamps[inside], z[inside]


def check_run(result, doc, clean, spec):
    """What holds for every fault: the run finishes with finite torques, the truth is the clean
    run's, the envelope holds, one report for the fault."""
    assert result.trace["tick"].size == BASE.loop.ticks
    assert np.isfinite(result.tau).all() and np.isfinite(result.tau_mpc).all()
    # the marks of the faults split the run into other chunks, and a motion evaluated on
    # shorter arrays may differ in the last bit (≤ 1e-17 m, rhmpc.sim.sensors.Sensor.measure)
    np.testing.assert_allclose(result.poi, clean[0].poi, rtol=0, atol=1e-15)
    assert doc["joint_envelope"]["held"] and result.envelope["held"]
    (report,) = doc["faults"]
    assert report["fault"] == spec and report["start_s"] == START
    for window in ("during", "after"):
        if report[window] is not None:
            assert report[window]["envelope_held"]
    return report


@pytest.mark.slow
def test_the_truth_is_the_clean_streams():
    faulty = build_run(BASE.replace(**{"faults.events": ("freeze@1.5:0.3", "jump@2:1mm")}))
    n = BASE.loop.ticks
    np.testing.assert_array_equal(faulty.truth.window(0, n), build_run(BASE).truth.window(0, n))
    assert faulty.stream.block(3000, 3001)[1][0, 0] != build_run(BASE).stream.block(
        3000, 3001)[1][0, 0]


@pytest.mark.slow
def test_a_frozen_sensor_repeats_its_last_sample(clean):
    result, doc = run("freeze@1.5:0.3")
    report = check_run(result, doc, clean, "freeze@1.5:0.3")
    stamps, z = samples_in(result, START, 1.8)
    _, z_clean = samples_in(clean[0], START, 1.8)
    assert stamps.size == 40 and np.all(np.diff(stamps) > 0)  # stamps advance
    np.testing.assert_array_equal(z, np.broadcast_to(z[0], z.shape))  # the value does not
    assert np.abs(z[1:] - z_clean[1:]).max() > 1e-4
    assert report["during"]["counts"]["missing"] == 0
    assert report["end_s"] == pytest.approx(1.8)


@pytest.mark.slow
def test_a_jump_is_rejected_then_followed_and_the_gate_says_so(clean):
    result, doc = run("jump@1.5:5mm")
    report = check_run(result, doc, clean, "jump@1.5:5mm")
    _, z = samples_in(result, START, 3.0)
    _, z_clean = samples_in(clean[0], START, 3.0)
    np.testing.assert_allclose(z - z_clean, np.broadcast_to([5e-3, 0, 0], z.shape), atol=1e-15)
    counts = report["during"]["counts"]
    assert counts["outliers_rejected"] == BASE.reference.outlier_max_rejections
    assert counts["gate_unlocked"] == 1
    assert report["after"] is None and report["end_s"] == 3.0  # to the end of the run


@pytest.mark.slow
def test_a_burst_of_nan_is_counted_sample_by_sample(clean):
    result, doc = run("nan@1.5:0.5")
    report = check_run(result, doc, clean, "nan@1.5:0.5")
    # refreshes on ticks 15 k stamped 15 k·Ts: k = 200 … 266 fall in [1.5, 2.0) s
    _, z = samples_in(result, START, 2.0)
    assert z.shape[0] == 67 and np.isnan(z).all()
    assert report["during"]["counts"]["missing"] == 67
    assert report["during"]["counts"]["outliers_rejected"] == 0
    assert report["after"]["counts"]["missing"] == 0


@pytest.mark.slow
def test_a_short_encoder_stick_is_held_tick_by_tick(clean):
    result, doc = run("stick@1.5:0.02")
    report = check_run(result, doc, clean, "stick@1.5:0.02")
    assert report["during"]["counts"]["encoder_held_ticks"] == 40  # 20 ms at 2 kHz
    assert report["after"]["counts"]["encoder_held_ticks"] == 0
    np.testing.assert_array_equal(result.samples[1], clean[0].samples[1])  # the sensor is fine
    text = format_summary(doc)
    assert "fault            stick@1.5:0.02 (1.5–1.52 s)" in text
    assert "encoder ticks held 40" in text and "joint envelope   held" in text


@pytest.mark.slow
def test_the_envelope_holds_through_a_stuck_encoder(clean):
    """0.2 s of stuck encoders: the observer's gate holds the readings out, the controller
    brakes after the fault timeout and tracks again once the readings move."""
    result, doc = run("stick@1.5:0.2")
    assert doc["faults"][0]["during"]["counts"]["encoder_held_ticks"] == 400
    check_run(result, doc, clean, "stick@1.5:0.2")
    assert doc["controller"]["failures"].get("encoder_fault", 0) > 0
    assert doc["encoder"]["held"] > 0 and doc["encoder"]["reacquired"] <= 1


@pytest.mark.slow
def test_a_slow_sensors_raw_samples_carry_the_fault():
    """3-D ultrasound at 28 Hz: the predictor reads each raw sample at its arrival, 68 ms
    late; every raw sample measured in the burst is missing for it."""
    config = BASE.replace(sensor="ultrasound", **{"faults.events": ("nan@1.5:0.5",)})
    t = build_run(config).stream.block(0, 200)[0]
    lost = int(((t >= START) & (t < 2.0)).sum())
    _, doc = run_experiment(config)
    report = doc["faults"][0]
    assert lost == 14
    assert report["during"]["counts"]["missing"] + report["after"]["counts"]["missing"] == lost
