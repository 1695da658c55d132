"""Faults injected into a closed loop, and what each one did to the run.

The faults of :mod:`rhmpc.sim.sensors.faults` act on what the controller reads, never on the truth,
each on the stream its kind declares (``target``) and by its own ``corrupt``:

- the sensor's samples, block by block (:class:`rhmpc.sim.sensors.faults.FaultySamples`);
- the plant's ``encoders()``, tick by tick (:class:`FaultyEncoders`: the arm moves on).

What each fault did to the run is the document's (:mod:`rhmpc.experiment.faults`).
"""

from __future__ import annotations

import math

import numpy as np

from rhmpc.sim.loop.clock import arrival_tick

__all__ = ["FaultyEncoders", "split_faults"]

def split_faults(faults) -> tuple[tuple, tuple]:
    """(the faults on the sensor's samples, those on the encoders) of ``faults``."""
    return (tuple(f for f in faults if f.target == "samples"),
            tuple(f for f in faults if f.target == "encoders"))


class FaultyEncoders:
    """A plant whose encoder readings a fault corrupts
    (:class:`~rhmpc.sim.sensors.faults.EncoderStick`).

    On tick ``i`` (time ``i·Ts``, counted by ``step``) inside a fault's window, ``encoders()``
    returns the reading as the fault's ``corrupt`` leaves it, the reading of the tick before the
    window the held one; ``held_ticks`` counts the ticks with a corrupted reading. Everything
    else is the plant's (``q``, ``step`` …): the arm moves on.
    """

    def __init__(self, plant, faults, Ts: float) -> None:
        self.plant, self.faults, self.Ts = plant, tuple(faults), Ts
        nq = np.size(plant.encoders())
        for f in self.faults:
            f.columns(nq)  # ValueError for a joint the arm does not have
        self.windows = [(arrival_tick(f.start_s, Ts),
                         math.inf if math.isinf(f.end_s) else arrival_tick(f.end_s, Ts))
                        for f in self.faults]
        self._held: list[np.ndarray | None] = [None] * len(self.faults)
        self._last: np.ndarray | None = None
        self.tick = 0
        self.held_ticks = 0

    def encoders(self) -> np.ndarray:
        reading = self.plant.encoders()
        i, out = self.tick, reading
        for k, (fault, (a, b)) in enumerate(zip(self.faults, self.windows, strict=True)):
            if a <= i < b:
                if self._held[k] is None:
                    self._held[k] = np.array(reading if self._last is None else self._last)
                rows = out[None]
                corrupted = fault.corrupt(np.array([i * self.Ts]), rows, self._held[k])
                out = out if corrupted is rows else corrupted[0]
        if out is not reading:
            self.held_ticks += 1
        self._last = out
        return out

    def step(self, tau: np.ndarray):
        self.tick += 1
        return self.plant.step(tau)

    def __getattr__(self, name: str):
        return getattr(self.plant, name)
