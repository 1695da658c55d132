"""Fixtures shared across the test suite: the PHANToM and its linear model."""

from __future__ import annotations

import pytest

from rhmpc.robots import LinearArm, Robot, linearize, load_robot


@pytest.fixture(scope="session")
def phantom() -> Robot:
    """The PHANToM Premium 1.5A (the default robot), loaded once per test run."""
    return load_robot("phantom")


@pytest.fixture(scope="session")
def arm(phantom: Robot) -> LinearArm:
    """The PHANToM linearised about its home posture at Ts = 0.5 ms (the MPC's model)."""
    return linearize(phantom)


@pytest.fixture(autouse=True)
def _no_model_cache(monkeypatch: pytest.MonkeyPatch) -> None:
    """No test reads or fills the user's cache of fitted models
    (:mod:`rhmpc.experiment.model_cache`); its own tests give it a folder of theirs."""
    monkeypatch.setenv("RHMPC_MODEL_CACHE", "off")
