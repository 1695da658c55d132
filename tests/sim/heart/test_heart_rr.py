"""Heart phase driven by RR intervals: real PhysioNet annotations and the synthetic generator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rhmpc.sim.heart import (
    PhaseTrack,
    RRSettings,
    beat_times_from_annotations,
    beat_times_from_rr,
    make_scenario,
    rr_from_annotations,
    synthetic_rr,
)
from rhmpc.sim.heart.rr import RECORDS_DIR, find_record, shipped_records

MITDB_100 = RECORDS_DIR / "mitdb-100" / "100"
REC_1003 = RECORDS_DIR / "1003" / "1003"


def test_mitdb_100_rr_statistics() -> None:
    """README: 2 273 beats (2 239 N + 33 A + 1 V), mean RR 0.795 s, σ 0.049 s, 0.522–1.131 s."""
    rr = rr_from_annotations(MITDB_100)
    assert rr.size == 2239 + 33 + 1 - 1  # the rhythm annotation '+' is skipped
    assert rr.mean() == pytest.approx(0.795, abs=0.002)
    assert rr.std() == pytest.approx(0.049, abs=0.002)
    assert rr.min() == pytest.approx(0.522, abs=0.002)
    assert rr.max() == pytest.approx(1.131, abs=0.002)


def test_record_path_forms_agree() -> None:
    a = rr_from_annotations(MITDB_100)
    b = rr_from_annotations(str(MITDB_100) + ".atr")
    c = rr_from_annotations(MITDB_100.parent)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    with pytest.raises(ValueError, match="no annotation file"):
        rr_from_annotations(MITDB_100.parent / "999")


def test_shipped_records_by_name_from_any_directory(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped copies resolve by name outside the repository; a path still wins."""
    monkeypatch.chdir(tmp_path)
    assert set(shipped_records()) == {"mitdb-100", "1003"}
    for name in ("mitdb-100", "100", "mitdb-100/100", "100.atr"):
        assert find_record(name) == MITDB_100
    assert find_record("1003") == REC_1003
    np.testing.assert_array_equal(rr_from_annotations("mitdb-100"),
                                  rr_from_annotations(MITDB_100))
    local = tmp_path / "mine"
    local.mkdir()
    for suffix in (".hea", ".atr"):
        (local / f"100{suffix}").write_bytes(MITDB_100.with_suffix(suffix).read_bytes())
    assert find_record("mine") == Path("mine", "100")  # relative, as given
    with pytest.raises(ValueError, match="nor a shipped record: 1003, mitdb-100"):
        find_record("nope")


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_premature_beats_are_kept() -> None:
    """The 33 atrial premature beats show as short RR intervals followed by long ones."""
    import wfdb

    ann = wfdb.rdann(str(MITDB_100), "atr")
    beats = [(s, sym) for s, sym in zip(ann.sample, ann.symbol, strict=True) if sym != "+"]
    times = beat_times_from_annotations(MITDB_100)
    assert times.size == len(beats)
    premature = [i for i, (_, sym) in enumerate(beats) if sym == "A"]
    assert len(premature) == 33
    rr = np.diff(times)
    short = rr[[i - 1 for i in premature if i > 0]]
    assert np.median(short) < 0.85 * np.median(rr)


def test_record_1003() -> None:
    rr = rr_from_annotations(REC_1003)
    assert rr.size == 956
    assert 60 / rr.mean() == pytest.approx(95.7, abs=0.3)
    assert rr.std() == pytest.approx(0.015, abs=0.003)


@pytest.mark.parametrize("record", [MITDB_100, REC_1003])
def test_rr_driven_beat_times_equal_annotation_times(record: Path) -> None:
    """φ(t_i) = i at the annotated beats: the motion's beat onsets are the annotation times."""
    times = beat_times_from_annotations(record)
    rr = np.diff(times)
    sc = make_scenario("fixed-a2-top", rr=rr, rr_start=times[0])
    phase = sc.source.phase
    np.testing.assert_allclose(phase(times), np.arange(times.size), atol=1e-9)
    found = phase.beat_times(times[0] - 1e-6, times[-1] + 1e-6)
    np.testing.assert_allclose(found, times, atol=1e-7)
    assert sc.duration == pytest.approx(min(472.0, times[-1] - times[0]))
    # the same with the record path
    by_record = make_scenario("fixed-a2-top", record=record)
    np.testing.assert_allclose(by_record.source.phase(times - times[0]),
                               np.arange(times.size), atol=1e-9)


def test_rr_driven_motion_repeats_with_each_beat() -> None:
    """Beat-by-beat time warping: same phase within a beat → same cardiac displacement."""
    rr = np.array([0.8, 0.6, 1.0, 0.7, 0.9, 0.75])
    sc = make_scenario("fixed-a2-top", rr=rr, breathing=False, coupling=0.0,
                       beat_gain_std=0.0, variability="clean")
    tb = beat_times_from_rr(rr)
    ph = sc.source.phase
    np.testing.assert_allclose(ph(tb), np.arange(tb.size), atol=1e-12)
    # start of beats 1..5 are all at phase 0 of the morphology → same position
    p = sc.source.position(tb[1:-1])
    np.testing.assert_allclose(p, np.broadcast_to(p[0], p.shape), atol=1e-12)
    rate = ph.rate(np.linspace(tb[0], tb[-1], 2000))
    assert np.all(rate > 0)


def test_phase_track_rate_profile_integrates() -> None:
    """φ(t) = ∫ f_h dτ exactly for a piecewise-linear rate; linear extrapolation outside."""
    track = PhaseTrack.from_rate_knots(np.array([0.0, 10.0, 20.0]),
                                       np.array([1.0, 2.0, 2.0]), phase0=0.25)
    assert float(track(10.0)) == pytest.approx(0.25 + 15.0)
    assert float(track(20.0)) == pytest.approx(0.25 + 35.0)
    assert float(track(25.0)) == pytest.approx(0.25 + 45.0)
    assert float(track(-1.0)) == pytest.approx(0.25 - 1.0)
    with pytest.raises(ValueError):
        PhaseTrack.from_rate_knots(np.array([0.0, 1.0]), np.array([1.0, -1.0]))
    with pytest.raises(ValueError):
        PhaseTrack.from_beat_times(np.array([0.0, 1.0, 0.5]))


def test_synthetic_rr_statistics_and_seed() -> None:
    cfg = RRSettings(mean_rate=1.25, std=0.05)
    rr = synthetic_rr(600.0, np.random.default_rng(3), cfg)
    assert rr.sum() >= 600.0
    assert 1 / rr.mean() == pytest.approx(1.25, rel=0.03)
    assert rr.std() == pytest.approx(0.05, rel=0.35)
    np.testing.assert_array_equal(rr, synthetic_rr(600.0, np.random.default_rng(3), cfg))
    assert not np.array_equal(rr, synthetic_rr(600.0, np.random.default_rng(4), cfg))
    # LF/HF modulation: the RR tachogram has power near 0.1 and 0.25 Hz
    tb = np.cumsum(rr)
    grid = np.arange(tb[0], tb[-1], 0.25)
    x = np.interp(grid, tb, rr)
    spec = np.abs(np.fft.rfft(x - x.mean())) ** 2
    f = np.fft.rfftfreq(grid.size, 0.25)

    def power(lo: float, hi: float) -> float:
        return float(spec[(f > lo) & (f < hi)].mean())

    assert power(0.07, 0.13) > 5 * power(0.4, 1.0)
    assert power(0.22, 0.28) > 5 * power(0.4, 1.0)


def test_synthetic_rr_drives_a_scenario() -> None:
    rr = synthetic_rr(60.0, np.random.default_rng(1))
    sc = make_scenario("fixed-a2-top", rr=rr)
    tb = beat_times_from_rr(rr)
    np.testing.assert_allclose(sc.source.phase(tb), np.arange(tb.size), atol=1e-9)
    assert sc.duration == pytest.approx(tb[-1])
    assert "RR-driven" in sc.description
