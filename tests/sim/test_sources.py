"""A run's heart source: scenario draws over the run's length, recordings shifted to t = 0."""

import numpy as np

from rhmpc.sim.heart.scenarios import SPECS
from rhmpc.sim.sources import heart_source


def test_motion_stays_physiological_past_the_scenarios_nominal_length() -> None:
    """Drawn over the nominal length only, the drift and breathing processes would be
    extrapolated cubics past it (a POI metres away in a 30-min run). Drawn over the run, the
    motion keeps its size: measured max |p| 4.97 mm over 1800 s (fixed-a2-top: p-p 8.39 mm),
    asserted < 6 mm."""
    nominal = SPECS["fixed-a2-top"].duration
    heart = heart_source("fixed-a2-top", np.random.default_rng(0), needed=3 * nominal)
    assert heart.duration >= 3 * nominal
    t = np.arange(0.0, 3 * nominal, 0.25)
    assert np.abs(np.asarray(heart.motion.position(t))).max() < 6e-3
    # a run within the nominal length draws the same motion whatever its length
    a = heart_source("fixed-a2-top", np.random.default_rng(0), needed=31.0).motion
    b = heart_source("fixed-a2-top", np.random.default_rng(0), needed=61.0).motion
    np.testing.assert_array_equal(a.position(t[:100]), b.position(t[:100]))


def test_a_recording_starts_at_zero(tmp_path) -> None:
    path = tmp_path / "rec.csv"
    t = 5.0 + np.arange(200) / 100.0
    z = np.c_[np.sin(t), np.cos(t), t] * 1e3  # mm
    np.savetxt(path, np.c_[t, z], delimiter=",", header="t,x,y,z", comments="")
    heart = heart_source("unused", np.random.default_rng(0), data=str(path))
    assert heart.label == "file:rec.csv"
    np.testing.assert_allclose(heart.motion.position(0.0), z[0] * 1e-3)
    np.testing.assert_allclose(heart.duration, 2.0)  # 200 samples at 100 Hz
