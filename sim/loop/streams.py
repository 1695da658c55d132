"""The loop's view of its open-loop inputs, read in blocks: memory that does not grow.

A run of ``n`` ticks needs, at 2 kHz, the sensor samples the controller sees and the true POI
position at every tick; the loop reads both in blocks:

- :class:`StreamCursor` walks a sample source (:mod:`rhmpc.sim.sensors.stream`) forward in time: the
  newest sample arrived by a given instant;
- a *truth* has ``center`` (the POI's mean over the run), ``n_ticks`` and ``window(i0, i1)``, the
  centred positions of ticks ``i0 … i1 − 1``: :class:`rhmpc.sim.loop.exact.ArrayTruth` wraps
  an array, :class:`SourceTruth` evaluates a motion source per window (two passes: the mean,
  then the run).

Only the mean is not identical to the whole-array ``np.nanmean``: it is summed per block, which
changes its last bits (≤ 1e-19 m for millimetre motion, far below anything printed).
"""

from __future__ import annotations

import bisect

import numpy as np

from rhmpc.sim.sensors.stream import BLOCK


class StreamCursor:
    """The newest sample arrived by a time that only moves forward.

    ``newest(now)`` is ``searchsorted(arrival, now, "right") − 1`` over the whole stream (−1
    before the first arrival), read one :data:`BLOCK` at a time; ``sample(j)`` is ``(t_j, z_j)``
    for an index ``newest`` returned last.
    """

    def __init__(self, samples, block: int = BLOCK) -> None:
        self.samples, self.size, self.n = samples, block, len(samples)
        self._b = -1
        self._current = self._previous = None
        self._advance()

    def _advance(self) -> None:
        self._b += 1
        a = self._b * self.size
        self._previous = self._current
        self._current = self.samples.block(a, min(a + self.size, self.n))
        self._arrival = self._current[2].tolist()  # bisect on floats: no NumPy call a tick

    def newest(self, now: float) -> int:
        arrival = self._arrival
        while arrival and arrival[-1] <= now and (self._b + 1) * self.size < self.n:
            self._advance()
            arrival = self._arrival
        k = bisect.bisect_right(arrival, now) - 1  # searchsorted(…, "right") − 1
        return self._b * self.size + k  # k = −1: the previous block's last sample (or −1)

    def sample(self, j: int) -> tuple[float, np.ndarray]:
        k = j - self._b * self.size
        t, z, _ = self._current if k >= 0 else self._previous
        return float(t[k]), z[k]


def measurements(z: np.ndarray) -> np.ndarray:
    """Samples (n, d) with every one that is no measurement (a non-finite component, or a
    squared norm that overflows: ‖z‖ > 1e154) set to NaN, as the predictors take them
    (:func:`rhmpc.predictors.base.is_measured`): no score is taken against them."""
    z = np.asarray(z, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        bad = ~np.isfinite(np.einsum("ij,ij->i", z, z))
    if not bad.any():
        return z
    z = z.copy()
    z[bad] = np.nan
    return z


class SourceTruth:
    """Centred POI truth ``p(i·Ts) − mean`` of a motion source, evaluated per window.

    The mean over ticks 0 … n_ticks − 1 (NaN ignored per axis) is made in a first pass of
    ``chunk`` ticks; ``centred=False`` keeps the motion's own coordinates (``center`` zero, the
    mean still checked for a finite sample). ``source`` may instead be a sample source
    (``ground_truth = "recorded"``): the truth is then the stream linearly interpolated at the
    tick times (:class:`rhmpc.sim.recordings.RecordedMotion` on the samples around each window), its
    samples that are no measurements missing (:func:`measurements`).
    """

    def __init__(self, source, n_ticks: int, Ts: float, chunk: int = 20_000,
                 centred: bool = True) -> None:
        self.source, self.n_ticks, self.Ts = source, int(n_ticks), float(Ts)
        #: indices of the recorded samples that are no measurements (missing for the truth)
        self.unmeasured: set[int] = set()
        total, count = None, None
        for i0 in range(0, self.n_ticks, chunk):
            p = self._raw(i0, min(i0 + chunk, self.n_ticks))
            finite = np.isfinite(p)
            s = np.where(finite, p, 0.0).sum(axis=0)
            total = s if total is None else total + s
            count = finite.sum(axis=0) if count is None else count + finite.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            self.center = total / count
        if not np.all(np.isfinite(self.center)):
            raise ValueError("the heart motion has no finite sample over the run")
        if not centred:
            self.center = np.zeros_like(self.center)
        self.dim = self.center.size

    def _raw(self, i0: int, i1: int) -> np.ndarray:
        t = np.arange(i0, i1) * self.Ts
        if hasattr(self.source, "block"):
            from rhmpc.sim.recordings import RecordedMotion

            a = max(self.source.index_at(t[0]) - 2, 0)
            b = min(self.source.index_at(t[-1]) + 3, len(self.source))
            ts, z, _ = self.source.block(a, b)
            z = measurements(z)
            self.unmeasured.update((a + np.flatnonzero(np.isnan(z).any(axis=1))).tolist())
            return RecordedMotion(ts, z, name="recorded stream").position(t)
        return np.asarray(self.source.position(t), dtype=float).reshape(t.size, -1)

    def window(self, i0: int, i1: int) -> np.ndarray:
        i1 = min(i1, self.n_ticks)
        return self._raw(i0, i1) - self.center
