"""The score at a recording's measured instants (rhmpc.sim.loop.metrics.MeasuredScore), against a
direct computation written here: the tool's path interpolated at each sample's instant."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.loop.metrics import MeasuredScore

TS = 0.5e-3


def _direct(t, p, ee, start, stop, left_out=()):
    """RMS and max [mm] of ‖p_ee(t_k) − p_k‖ over start ≤ t_k < stop, p_ee linear between the
    states at (i + 1)·Ts (the state before the first tick at time 0 is ``ee[0]`` held)."""
    times = np.r_[0.0, (1 + np.arange(ee.shape[0])) * TS]
    path = np.vstack([ee[:1], ee])
    keep = (t >= start - 1e-9) & (t < stop - 1e-9) & np.isfinite(p).all(axis=1)
    keep &= ~np.isin(np.arange(t.size), left_out)
    tool = np.column_stack([np.interp(t[keep], times, path[:, a]) for a in range(3)])
    e = np.linalg.norm(tool - p[keep], axis=1)
    return 1e3 * np.sqrt(np.mean(e**2)), 1e3 * e.max(), int(keep.sum())


def _score_in_chunks(t, p, ee, start, stop, chunks, outliers=()):
    score = MeasuredScore(t, p, start, stop, TS)
    c0 = 0
    for size in chunks:
        score.add(c0, ee[c0 : c0 + size])
        score.fold(list(outliers), c0 * TS - 0.05)
        c0 += size
    score.fold(list(outliers))
    return score


@pytest.mark.parametrize("rate", [25.0, 28.0, 257.0])
def test_the_score_is_the_tool_at_each_sample_instant(rate: float) -> None:
    """25 Hz lies on the 2-kHz grid, 28 Hz and 257 Hz do not: the tool is interpolated between
    the ticks around each instant; chunks of any size give the same score (1e-12)."""
    rng = np.random.default_rng(7)
    n_ticks = 8000
    ee = np.cumsum(rng.normal(0.0, 1e-6, (n_ticks, 3)), axis=0)
    t = np.arange(0.0, n_ticks * TS, 1.0 / rate)
    p = 1e-4 * rng.normal(size=(t.size, 3))
    p[5] = np.nan  # no measurement
    start, stop = 1.0, n_ticks * TS
    want = _direct(t, p, ee, start, stop)
    for chunks in ([n_ticks], [1000] * 8, [333] * 24 + [8]):
        got = _score_in_chunks(t, p, ee, start, stop, chunks).result()
        np.testing.assert_allclose(got["rms_error_mm"], want[0], rtol=1e-12)
        np.testing.assert_allclose(got["max_error_mm"], want[1], rtol=1e-12)
        assert got["scored_samples"] == want[2]


def test_outliers_and_non_measurements_are_left_out_and_counted() -> None:
    rng = np.random.default_rng(3)
    n_ticks = 4000
    ee = rng.normal(0.0, 1e-4, (n_ticks, 3))
    t = np.arange(0.0, n_ticks * TS, 0.04)  # 25 Hz: 50 samples
    p = rng.normal(0.0, 1e-4, (t.size, 3))
    p[[10, 30]] = np.nan
    outliers = [t[20], t[21], t[40]]
    score = _score_in_chunks(t, p, ee, 0.4, n_ticks * TS, [500] * 8, outliers)
    want = _direct(t, p, ee, 0.4, n_ticks * TS, left_out=[20, 21, 40])
    np.testing.assert_allclose(score.result()["rms_error_mm"], want[0], rtol=1e-12)
    assert score.outliers == 3 and score.unmeasured == 2
    _, _, scored = score.samples()
    assert scored.sum() == want[2] == score.result()["scored_samples"]
    assert not scored[[20, 21, 40, 10, 30]].any() and not scored[:10].any()  # settling


def test_the_span_is_half_open_and_the_trace_keeps_the_ticks_at_the_instants() -> None:
    t = np.arange(0.0, 2.0, 0.04)
    p = np.zeros((t.size, 3))
    score = MeasuredScore(t, p, 1.0, 1.6, TS)
    assert score.t[score.first] == pytest.approx(1.0) and score.stop - score.first == 15
    rows = score.rows(1000, 1000)  # the states after ticks 1000 … 1999, times 0.5005 … 1.0
    assert np.flatnonzero(rows).tolist() == [999]  # time 1.0 = (1000 + 999 + 1)·Ts
    off = MeasuredScore(np.array([1.00025]), np.zeros((1, 3)), 0.0, 2.0, TS)
    assert np.flatnonzero(off.rows(1999, 4)).tolist() == [0, 1]  # both ticks around it
