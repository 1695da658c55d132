"""A recording's heart rate from its spectrum (rhmpc.sim.heart.analysis): over time, and not from
too little data."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.heart.analysis import heart_rate_track, motion_stats
from rhmpc.sim.recordings import RecordedMotion


def test_the_track_follows_a_rate_step() -> None:
    rate = 25.0
    t = np.arange(0.0, 60.0, 1 / rate)
    f = np.where(t < 30.0, 1.2, 1.5)  # 72, then 90 beats/min
    phase = 2 * np.pi * np.cumsum(f) / rate
    z = np.column_stack([np.sin(phase), 0.5 * np.cos(phase), np.sin(2 * np.pi * 0.25 * t)])
    centres, hz = heart_rate_track(t, z, rate)
    assert centres[0] == pytest.approx(5.0) and np.all(np.diff(centres) == pytest.approx(2.0))
    assert 60 * hz[centres < 24] == pytest.approx(72.0, abs=0.6)
    assert 60 * hz[centres > 36] == pytest.approx(90.0, abs=0.6)
    assert heart_rate_track(t[:200], z[:200], rate)[0].size == 0  # shorter than a window


def test_no_heart_rate_from_too_few_complete_samples() -> None:
    t = np.arange(0.0, 10.0, 0.04)
    z = np.sin(2 * np.pi * 1.2 * t)[:, None] * 1e-3
    z[50:] = np.nan  # 2 s of data: less than two periods at 0.7 Hz
    stats = motion_stats(RecordedMotion(t, z), 9.96, 25.0)
    assert np.isnan(stats.heart_rate).all()
    assert stats.as_dict()["heart_rate_bpm"] == [None, None]
    whole = motion_stats(RecordedMotion(t, np.sin(2 * np.pi * 1.2 * t)[:, None]), 9.96, 25.0)
    assert 60 * whole.heart_rate[0] == pytest.approx(72.0, abs=3.0)
