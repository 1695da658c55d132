"""The physical sonomicrometer against its physics, each test with its tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.heart import make_scenario
from rhmpc.sim.sensors import (
    CrystalArray,
    Sonomicrometer,
    SonomicrometrySettings,
    dilution,
    sensor_from_name,
    sonomicrometry,
    trilaterate,
)

QUIET = dict(sound_speed_error=0.0, orientation_error=False, slip_rate=0.0, range_noise=0.0)


@pytest.fixture(scope="module")
def source():
    return make_scenario("fixed-a2-top", duration=130.0).source


def _error(stream, source) -> np.ndarray:
    return stream.z - source.position(stream.t)


def test_trilateration_is_exact_without_errors(source) -> None:
    """Tolerance 1e-12 m: the closed form plus Gauss–Newton solves exact ranges exactly."""
    s = sonomicrometry(SonomicrometrySettings(clock=0.0, **QUIET)).measure(
        source, 5.0, np.random.default_rng(0))
    assert np.abs(_error(s, source)).max() < 1e-12
    b = CrystalArray(count=6, angles=(0, 50, 100, 170, 230, 300)).positions()
    b[:, 2] = [0, 1e-3, -2e-3, 0, 3e-3, 0]  # not coplanar: the general closed form
    x = np.random.default_rng(1).uniform(-0.01, 0.01, (50, 3)) + np.array([0, 0, 0.03])
    r = np.linalg.norm(x[:, None, :] - b[None], axis=2)
    np.testing.assert_allclose(trilaterate(b, r), x, atol=1e-12)


def test_resolution_limited_noise_per_axis(source) -> None:
    """Counter step only: σ_axis = √diag((JᵀJ)⁻¹)·cΔ/√12 (uniform rounding error per range,
    linearised least squares), within 15 % per axis."""
    cfg = SonomicrometrySettings(**QUIET)
    s = sonomicrometry(cfg).measure(source, 120.0, np.random.default_rng(2))
    step = cfg.sound_speed * cfg.clock  # 12.4 µm
    assert step == pytest.approx(12.4e-6, rel=0.01)
    expected = dilution(cfg.crystals.positions(), cfg.crystals.poi()) * step / np.sqrt(12)
    np.testing.assert_allclose(_error(s, source).std(axis=0), expected, rtol=0.15)


def _above(e: np.ndarray, fs: float, cut: float = 26.0) -> float:
    spec = np.fft.rfft(e - e.mean(axis=0), axis=0)
    spec[np.fft.rfftfreq(len(e), 1 / fs) <= cut] = 0
    return float(np.sqrt(np.mean(np.sum(np.fft.irfft(spec, n=len(e), axis=0) ** 2, axis=1))))


@pytest.mark.slow
def test_content_above_26_hz_and_absolute_error() -> None:
    """Tuna §III-B: recorded − true above 26 Hz 0.10–0.14 mm RMS (3-D, slips excluded) on every
    seed; §III-A: 0.25 mm absolute accuracy per distance, ≤ 0.30 mm for the 95th percentile of
    the 3-D error on the median seed (fixed-a2-top, 60 s, default settings). The 95th
    percentile is set by the slow leading-edge and speed-of-sound errors, which vary with the
    run's draws: 0.07–0.25 mm without the white term, 0.23–0.35 mm with it over ten seeds, two
    of them above 0.30 mm at any white level of the 0.10–0.14 mm band."""
    above, p95 = [], []
    for seed in range(5):
        src = make_scenario("fixed-a2-top", np.random.default_rng(seed), duration=61.0).source
        s = sonomicrometry().measure(src, 60.0, np.random.default_rng(seed))
        e = _error(s, src)
        e = e[np.linalg.norm(e, axis=1) <= 1e-3]  # echo outliers (slips) excluded
        above.append(_above(e, s.rate))
        p95.append(np.percentile(np.linalg.norm(e, axis=1), 95))
    assert 0.10e-3 <= min(above) and max(above) <= 0.14e-3
    assert np.median(p95) <= 0.30e-3


def test_white_crystal_geometry_error_is_sized_from_section_3b() -> None:
    """The white range error σ_r: 0.12 mm RMS (3-D) above 26 Hz at 257 Hz by construction,
    σ_r = 0.12 mm / (G √(1 − 52/257)), G = ‖dilution‖ at the nominal POI (to 1 %); measured on
    a still POI (only the white term and the counter step): per-axis σ = dilution·σ_r within
    5 %, and 0.12 mm above 26 Hz within 5 %."""
    cfg = SonomicrometrySettings(**{**QUIET, "range_noise": SonomicrometrySettings().range_noise})
    axes = dilution(cfg.crystals.positions(), cfg.crystals.poi())
    G = float(np.linalg.norm(axes))
    assert G == pytest.approx(1.534, abs=1e-3)
    assert cfg.range_noise == pytest.approx(0.12e-3 / (G * np.sqrt(1 - 52 / 257)), rel=0.01)

    class Still:
        dim = 3

        @staticmethod
        def position(t):
            return np.zeros((np.size(t), 3))

    s = sonomicrometry(cfg).measure(Still(), 120.0, np.random.default_rng(7))
    e = s.z
    np.testing.assert_allclose(e.std(axis=0), axes * cfg.range_noise, rtol=0.05)
    assert _above(e, 257.0) == pytest.approx(0.12e-3, rel=0.05)


def test_leading_edge_error_is_bounded_and_smooth(source) -> None:
    """|δ_i| ≤ λ/4 on every range (exactly), and δ is smooth: ≥ 99 % of its variance below
    26 Hz (white noise at 257 Hz would put 80 % above)."""
    cfg = SonomicrometrySettings()
    stage = Sonomicrometer(cfg)
    t = np.arange(0, 60, 1 / 257)
    d = source.position(t) - source.position(t[:1])
    n0 = np.array([0.0, 0.0, 1.0])
    d_perp = d - np.outer(d @ n0, n0)
    x = cfg.crystals.poi() + d
    delta = stage.paths(x, d_perp) - np.linalg.norm(x[:, None] - cfg.crystals.positions(), axis=2)
    assert np.abs(delta).max() <= cfg.wavelength / 4 + 1e-15
    assert np.abs(delta).max() > 1e-6  # present
    assert _above(delta, 257.0) ** 2 <= 0.01 * np.mean(np.sum((delta - delta.mean(0)) ** 2, 1))


def test_cycle_slips_rate_and_size(source) -> None:
    """Slips: Poisson(rate·T) events (within 4σ), each moving the fix by one wavelength on one
    range, i.e. λ·‖(JᵀJ)⁻¹Jᵀ e_i‖ for some crystal i (within 5 %), never above 2.2 mm."""
    rate, span = 0.5, 120.0
    cfg = SonomicrometrySettings(**{**QUIET, "slip_rate": rate}, clock=0.0)
    s = sonomicrometry(cfg).measure(source, span, np.random.default_rng(4))
    jump = np.linalg.norm(_error(s, source), axis=1)
    hit = jump > 1e-9
    edges = np.flatnonzero(np.diff(np.concatenate([[0], hit.astype(int), [0]])))
    events = edges.size // 2
    assert abs(events - rate * span) <= 4 * np.sqrt(rate * span)
    b, x0 = cfg.crystals.positions(), cfg.crystals.poi()
    t_hit = s.t[hit]
    x = x0 + source.position(t_hit) - source.position(s.t[:1])  # the POI crystal at each slip
    for xk, jk in zip(x, jump[hit], strict=True):
        u = (xk - b) / np.linalg.norm(xk - b, axis=1, keepdims=True)
        sizes = cfg.wavelength * np.linalg.norm(np.linalg.pinv(u), axis=0)  # per crystal
        assert np.min(np.abs(jk - sizes) / sizes) <= 0.05
        assert jk <= 2.2e-3
    assert hit.mean() < 0.05


def test_seeded_draws_and_bad_settings(source) -> None:
    a = sonomicrometry().measure(source, 10.0, np.random.default_rng(5))
    b = sonomicrometry().measure(source, 10.0, np.random.default_rng(5))
    c = sonomicrometry().measure(source, 10.0, np.random.default_rng(6))
    np.testing.assert_array_equal(a.z, b.z)
    assert not np.array_equal(a.z, c.z)  # another speed-of-sound draw
    for bad in ({"crystals": 3}, {"diameter": -0.02}, {"standoff": float("nan")},
                {"sound_speed": float("inf")}, {"slip_rate": -1.0}):
        with pytest.raises(ValueError):
            sensor_from_name("sonomicrometry", **bad)
    with pytest.raises(TypeError):
        sensor_from_name("sonomicrometry", noise=1e-4)


def test_one_dimensional_motion_runs_along_the_first_axis() -> None:
    src = make_scenario("mitral-1d").source
    s = sonomicrometry().measure(src, 10.0, np.random.default_rng(0))
    assert s.z.shape == (2571, 1)
    assert np.percentile(np.abs(_error(s, src)), 95) < 0.30e-3


def test_measuring_in_blocks_gives_the_same_stream(monkeypatch) -> None:
    """Memory: the ranges and trilateration run in blocks; the stream does not depend on the
    block size (each sample is solved on its own; the run's draws come first). Bitwise."""
    from rhmpc.sim.heart.scenarios import make_scenario
    from rhmpc.sim.sensors import sonomicrometry
    from rhmpc.sim.sensors.sonomicrometry import Sonomicrometer

    scn = make_scenario("fixed-a2-top", np.random.default_rng(1))
    whole = sonomicrometry().measure(scn.source, 40.0, np.random.default_rng(2))
    monkeypatch.setattr(Sonomicrometer, "BLOCK", 777)
    blocks = sonomicrometry().measure(scn.source, 40.0, np.random.default_rng(2))
    np.testing.assert_array_equal(blocks.z, whole.z)
