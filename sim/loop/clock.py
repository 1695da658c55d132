"""When the predictor runs: on the 2-kHz stream every ``downsample`` ticks, or on each raw sample.

A sensor faster than the predictor's period (Tuna et al.'s 257-Hz sonomicrometer against a
7.5-ms predictor) is read on the stream delivered to the control rate, every ``downsample``
ticks. A slower one (video at 25 Hz, 3-D ultrasound at 28 Hz) would be read mostly between its
samples: a 25-Hz track interpolated behind its newest sample is a raw period (40 ms) late before
the predictor sees it. Such a sensor's raw samples go to the predictor once each, at their
arrival, with their own time stamps, and the predictor runs at the sensor's rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rhmpc.sim.loop.settings import LoopSettings
from rhmpc.sim.sensors.stream import SampledSamples, SampleSource, as_samples

#: Raw samples read to estimate a stream's rate.
RATE_SAMPLES = 4096


@dataclass(frozen=True)
class PredictorClock:
    """The predictor's clock in a run.

    Attributes
    ----------
    mode : str
        ``"downsample"`` or ``"sensor"`` (:attr:`LoopSettings.predictor_clock`).
    dt : float
        The predictor's period [s]: ``downsample·Ts``, or the raw sample period.
    refresh_ticks : int
        The most ticks one forecast must cover before the next: ``downsample``, or ⌈1.5·dt/Ts⌉
        for the raw samples (a late sample leaves the reference on the last forecast).
    sensor_rate : float
        The sensor's raw sample rate [Hz] (median interval).
    raw : SampleSource or None
        The raw samples the predictor reads (``"sensor"`` mode).
    """

    mode: str
    dt: float
    refresh_ticks: int
    sensor_rate: float
    raw: SampleSource | None = None

    def describe(self, playback: str | None = None) -> str:
        """One line for the run's summary."""
        if self.mode == "sensor":
            return (f"predictor on raw samples at {self.sensor_rate:g} Hz, each at its arrival "
                    "(the latency is predicted across)")
        how = f" ({playback} playback)" if playback else ""
        return (f"predictor every {self.dt * 1e3:g} ms on the {self.sensor_rate:g}-Hz sensor's "
                f"stream delivered at the control rate{how}")


def raw_samples(stream) -> SampleSource:
    """The sensor's samples as measured, before any delivery to the control rate."""
    samples = as_samples(stream)
    return getattr(samples, "recorded", samples)


def sample_rate(samples: SampleSource) -> float:
    """1 / median interval of the first samples [Hz] (inf for fewer than two)."""
    if isinstance(samples, SampledSamples):
        return float(samples.rate)
    t = np.asarray(samples.block(0, min(len(samples), RATE_SAMPLES))[0], dtype=float)
    gaps = np.diff(t)
    gaps = gaps[gaps > 0]
    return float(1.0 / np.median(gaps)) if gaps.size else math.inf


def predictor_clock(settings: LoopSettings, stream) -> PredictorClock:
    """The clock the predictor runs on for ``settings`` and the sensor ``stream``."""
    raw = raw_samples(stream)
    return clock_for_rate(settings, sample_rate(raw), raw)


def clock_for_rate(settings: LoopSettings, rate: float,
                   raw: SampleSource | None = None) -> PredictorClock:
    """The clock the predictor runs on for ``settings`` and a sensor of ``rate`` [Hz] (its raw
    samples ``raw``, which the ``"sensor"`` clock reads)."""
    period = settings.downsample * settings.Ts
    mode = settings.predictor_clock
    if mode == "auto":
        mode = "sensor" if rate * period < 1.0 - 1e-9 else "downsample"
    if mode == "downsample" or not math.isfinite(rate):
        return PredictorClock("downsample", period, settings.downsample, rate)
    dt = 1.0 / rate
    refresh = math.ceil(1.5 * dt / settings.Ts - 1e-9)
    return PredictorClock("sensor", dt, refresh, rate, raw)


def arrival_tick(arrival: float, Ts: float) -> int:
    """The first tick at or after ``arrival`` [s] (a sample is read on the tick it arrives)."""
    return max(0, math.ceil(arrival / Ts - 1e-9))
