"""Every model-based predictor beats ``hold`` on the in-vivo regime and on the Tuna replicas.

The protocol of the ``invivo-regime`` check on 40 s instead of 60: the true motion sampled at
25 Hz (seed 2), forecasts scored from sample 300 (12 s: the Fourier filters' 10-s fit and
2 s more), 3-D RMS of ẑ_{n+k|n} − z_{n+k} at every lead k = 1 … 5.
"""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.predictors import make_predictor
from rhmpc.predictors.monitor import rms_by_lead

RATE, SECONDS, SEED, WARMUP, LEADS = 25.0, 40.0, 2, 300, 5
SCENARIOS = ("invivo-video", "fixed-a1-top", "fixed-a2-top", "varying-a1-top",
             "varying-a3-top", "varying-a1-side", "varying-a3-side")
MODEL_BASED = ("ekf", "dual-ekf", "wflc", "ar", "fading-ar", "one-step", "generalized")
#: Predictors with a heart-rate estimate and the band it is held to [Hz].
RATE_BAND = {"ekf": (0.5, 3.5), "dual-ekf": (0.6, 3.0), "wflc": (0.6, 3.5)}


def _stream(scenario: str, seed: int = SEED) -> np.ndarray:
    sim_heart = pytest.importorskip("rhmpc.sim.heart")
    source = sim_heart.make_scenario(scenario, np.random.default_rng(seed)).source
    return np.asarray(source.position(np.arange(round(SECONDS * RATE) + 1) / RATE))


def _rms_by_lead(name: str, z: np.ndarray) -> np.ndarray:
    """(LEADS,) RMS forecast error of predictor ``name`` on ``z`` [m]."""
    return rms_by_lead(make_predictor(name, 1.0 / RATE), z, LEADS, WARMUP)


@pytest.fixture(scope="module", params=SCENARIOS)
def errors(request) -> tuple[str, dict[str, np.ndarray]]:
    z = _stream(request.param)
    names = ("hold", "last-cycle", *MODEL_BASED)
    return request.param, {name: _rms_by_lead(name, z) for name in names}


@pytest.mark.slow
def test_every_model_based_predictor_beats_hold_at_every_lead(errors) -> None:
    """Measured (60 s, seed 2), at 1 / 3 / 5 samples in vivo: ekf 0.76 / 0.81 / 0.75, dual-ekf
    0.68 / 0.72 / 0.64, wflc 0.68 / 0.76 / 0.70 × hold's; on the replicas at most 0.30."""
    scenario, rms = errors
    for name in MODEL_BASED:
        ratio = rms[name] / rms["hold"]
        assert np.all(ratio < 1.0), f"{scenario}: {name} / hold = {np.round(ratio, 2)}"


@pytest.mark.slow
def test_the_rls_predictors_beat_last_cycle(errors) -> None:
    scenario, rms = errors
    for name in ("one-step", "generalized"):
        assert np.all(rms[name] < rms["last-cycle"]), scenario


@pytest.mark.slow
def test_the_in_vivo_regime_is_as_hard_as_its_recording(errors) -> None:
    """one-step / hold at 3 samples: the recording 0.67 (check: ≥ 0.55); replicas ≤ 0.3."""
    scenario, rms = errors
    ratio = rms["one-step"][2] / rms["hold"][2]
    if scenario.startswith("invivo"):
        assert ratio >= 0.55
    else:
        assert ratio < 0.3


@pytest.mark.parametrize("name", sorted(RATE_BAND))
@pytest.mark.parametrize("kind", ["invivo-video", "white", "chirp"])
@pytest.mark.slow
def test_heart_rate_estimate_stays_in_the_band(name: str, kind: str) -> None:
    """By construction: clamps and re-fits hold ω̂ inside the band, whatever the input."""
    rng = np.random.default_rng(7)
    t = np.arange(round(SECONDS * RATE)) / RATE
    if kind == "white":
        z = 1e-3 * rng.standard_normal((t.size, 3))
    elif kind == "chirp":  # 0.2 → 4.2 Hz
        z = 1e-3 * np.sin(2 * np.pi * (0.2 * t + 0.05 * t**2))[:, None] * np.ones(3)
    else:
        z = _stream(kind, seed=int(rng.integers(100)))[: t.size]
    lo, hi = RATE_BAND[name]
    p = make_predictor(name, 1.0 / RATE)
    rates = []
    for zk in z:
        p.update(zk)
        if p.ready:
            rates.append(p.heart_rate_hz)
    assert rates and lo <= min(rates) and max(rates) <= hi
