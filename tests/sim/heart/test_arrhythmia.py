"""The arrhythmia-apb scenario: MIT-BIH record 100's rhythm with premature-beat morphology."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.heart import make_scenario
from rhmpc.sim.heart.arrhythmia import POST_PAUSE_POTENTIATION, SHARED_DATA, premature_stroke
from rhmpc.sim.heart.rr import beats_from_annotations
from rhmpc.sim.heart.scenarios import SPECS

RECORD = SHARED_DATA / "mitdb-100" / "100"


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_phase_follows_the_annotations() -> None:
    """φ(t_i) = i at the record's beats in the window; 10 of the 33 A beats fall in it."""
    spec = SPECS["arrhythmia-apb"]
    times, premature = beats_from_annotations(RECORD)
    assert premature.sum() == 34  # 33 A + 1 V
    sc = make_scenario("arrhythmia-apb")
    assert sc.duration == spec.duration == 240.0
    inside = (times >= spec.record_start) & (times <= spec.record_start + spec.duration)
    assert premature[inside].sum() == 10
    local = times[inside] - spec.record_start
    phi = sc.source.phase(local)
    np.testing.assert_allclose(np.diff(phi), 1.0, atol=1e-9)


def test_premature_stroke_rule() -> None:
    """Premature beat: gain = coupling interval / median RR; the next beat is potentiated."""
    t = np.array([0.0, 0.8, 1.6, 2.16, 3.2, 4.0])
    premature = np.array([False, False, False, True, False, False])
    gain = premature_stroke(t, premature)
    assert gain[3] == pytest.approx(0.56 / 0.8)
    assert gain[4] == POST_PAUSE_POTENTIATION
    assert np.all(gain[[0, 1, 2, 5]] == 1.0)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_premature_beats_are_smaller_and_calibrated() -> None:
    sc = make_scenario("arrhythmia-apb", variability="clean", beat_gain_std=0.0,
                       breathing=False, coupling=0.0)
    spec = SPECS["arrhythmia-apb"]
    times, premature = beats_from_annotations(RECORD)
    local = times - spec.record_start
    idx = np.flatnonzero(premature & (local > 1) & (local < 239))
    rng_ = []
    for i in idx:
        t = np.linspace(local[i], local[i + 1], 200, endpoint=False)
        prev = np.linspace(local[i - 2], local[i - 1], 200, endpoint=False)
        rng_.append(np.ptp(sc.source.heartbeat(t)[:, 2]) / np.ptp(sc.source.heartbeat(prev)[:, 2]))
    assert np.median(rng_) < 0.9  # smaller stroke than a normal beat before it
    full = make_scenario("arrhythmia-apb")
    t = np.arange((240 * 257) + 1) / 257
    p = full.source.position(t)
    assert np.max(np.ptp(p, axis=0)) * 1e3 == pytest.approx(8.39, rel=0.02)
