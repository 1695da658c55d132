"""Bookkeeping shared by every predictor: the unit of the data, the recent signal range, and
the running forecast error per lead.

* :func:`infer_unit` — metres per data unit from an initialisation window, snapped to a
  power of 1000 (m, mm, µm), so that the SI parameters of the papers meet the data in
  the unit it was recorded in, and a predictor fed mm forecasts exactly 1000 × what it
  forecasts when fed m.
* :class:`RangeEnvelope` — the per-axis [min, max] of the valid samples of the last
  ``window`` samples, kept as block extrema (O(d) per sample, O(blocks·d) per query).
* :class:`LeadErrorRMS` — the exponentially weighted RMS of past forecast misses at each
  lead, e_k = ‖ẑ_{n+k|n} − z_{n+k}‖, from the forecasts the owner recorded.
* :func:`rms_by_lead` — the plain RMS of those misses over a whole stream, open loop: how a
  predictor is scored offline.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LeadErrorRMS", "RangeEnvelope", "infer_unit", "rms_by_lead"]

#: typical range of heart-surface motion within the inference window (0.5 s, less than a
#: beat) [m]: ≈ 2 mm, between a quiet diastasis (0.2 mm at 50 beats/min in the in-vivo regime)
#: and a systole (6–9 mm on the Tuna replicas, whose whole motion spans 5–15 mm, Tuna 2013
#: §VIII); ranges of 0.06–63 mm are then read as metres
TYPICAL_RANGE_M = 2e-3
#: typical distance of a sample from the origin when it does not move [m]
TYPICAL_POSITION_M = 0.1


def infer_unit(window: np.ndarray) -> float:
    """Metres per data unit, 1000^−k, for samples ``window`` (T, d) (NaN rows ignored).

    k = round(log₁₀₀₀(r / r₀)) with r the largest per-axis peak-to-peak range and
    r₀ = :data:`TYPICAL_RANGE_M` (2 mm): a range between 0.063 mm and 63 mm is read as
    metres, 0.063–63 m as millimetres (×1000), and so on.  A window that does not move is
    judged by its largest magnitude against :data:`TYPICAL_POSITION_M`; all zeros → 1.
    """
    x = np.asarray(window, dtype=float)
    x = x[np.isfinite(x).all(axis=1)]
    if x.size == 0:
        return 1.0
    r = float(np.max(x.max(axis=0) - x.min(axis=0)))
    ref = TYPICAL_RANGE_M
    if not r > 0.0:
        r, ref = float(np.max(np.abs(x))), TYPICAL_POSITION_M
        if not r > 0.0:
            return 1.0
    k = round(math.log10(r / ref) / 3.0)
    return 1000.0 ** (-max(-3, min(5, k)))


class RangeEnvelope:
    """Per-axis extrema of the valid samples among the last ``blocks × block`` updates."""

    def __init__(self, d: int, block: int, blocks: int = 8) -> None:
        self.block = max(1, int(block))
        self.lo = np.full((blocks, d), np.inf)
        self.hi = np.full((blocks, d), -np.inf)
        self._i = 0
        self._k = 0
        self.known = False
        self._env = (np.zeros(d), np.zeros(d))
        self._done = (np.full(d, np.inf), np.full(d, -np.inf))  # extrema of the full blocks

    def tick(self, x: np.ndarray | None) -> None:
        """Advance one update; ``x`` is the valid sample or ``None``."""
        if x is not None:
            np.minimum(self.lo[self._i], x, out=self.lo[self._i])
            np.maximum(self.hi[self._i], x, out=self.hi[self._i])
            self.known = True
        self._k += 1
        if self._k == self.block:
            self._k = 0
            self._i = (self._i + 1) % self.lo.shape[0]
            self.lo[self._i] = np.inf
            self.hi[self._i] = -np.inf
            self._done = (self.lo.min(axis=0), self.hi.max(axis=0))

    def envelope(self) -> tuple[np.ndarray, np.ndarray]:
        """(min, max) per axis of the window; the last known one through a long gap."""
        lo = np.minimum(self._done[0], self.lo[self._i])
        hi = np.maximum(self._done[1], self.hi[self._i])
        if lo[0] != np.inf:  # every axis is seen together
            self._env = (lo, hi)
        return self._env


class LeadErrorRMS:
    """Running RMS of forecast misses per lead, e_k = ‖ẑ_{n+k|n} − z_{n+k}‖ (data units).

    ``record(n, f)`` keeps the forecast f (K, d) made after update n (the latest one per
    n); ``observe(n, z)`` scores every recorded forecast that reaches sample n.  Each lead
    has its own exponentially weighted mean square with memory ``memory`` samples:
    m_k ← m_k + α (e_k² − m_k), α = max(1/memory, 1/count_k) (a plain mean at first).
    """

    def __init__(self, d: int, memory: float) -> None:
        self.d = d
        self.memory = max(1.0, float(memory))
        self.alpha = 1.0 / self.memory
        self.K = 0
        self._alloc(1)

    def _alloc(self, K: int) -> None:
        self.K = K
        self.fc = np.zeros((K, K, self.d))
        self.made = np.full(K, -1, dtype=np.int64)
        self.length = np.zeros(K, dtype=np.int64)
        self.ms = np.zeros(K)
        self.count = np.zeros(K)
        self._leads = np.arange(1, K + 1)
        self._k = self._leads - 1
        # ring rows of the forecasts made 1…K updates before an update landing on row j
        self._rows = (np.arange(K)[:, None] - self._leads[None, :]) % K
        # the same as flat indices into fc viewed as (K·K, d): one take instead of a 2-D gather
        self._flat = self._rows * K + self._k
        self._fc_rows = self.fc.reshape(K * K, self.d)
        # the fast path of observe: full-length forecasts recorded at consecutive updates
        # up to ``_last`` (``_run`` of them), and every lead past its memory
        self._last, self._run, self._steady = -1, 0, False

    def record(self, n: int, forecast: np.ndarray) -> None:
        K = forecast.shape[0]
        if K > self.K:
            self._alloc(K)
        row = n % self.K
        self.fc[row, :K] = forecast
        self.made[row] = n
        self.length[row] = K
        full = K == self.K
        self._run = (self._run + 1 if n == self._last + 1 else 1) if full else 0
        self._last = n

    def observe(self, n: int, z: np.ndarray) -> None:
        rows = self._rows[n % self.K]
        if self._steady and self._last == n - 1 and self._run >= self.K:
            # every lead has its forecast and α is constant: m ← m + α (e² − m)
            miss = np.take(self._fc_rows, self._flat[n % self.K], axis=0)
            miss -= z
            e2 = np.einsum("ij,ij->i", miss, miss)
            e2 -= self.ms
            e2 *= self.alpha
            self.ms += e2
            return
        made = n - self._leads
        ok = (self.made[rows] == made) & (self.length[rows] >= self._leads)
        miss = self.fc[rows, self._k] - z
        e2 = np.einsum("ij,ij->i", miss, miss)
        self.count += ok
        a = np.maximum(self.alpha, 1.0 / np.maximum(self.count, 1.0)) * ok
        self.ms += a * (e2 - self.ms)
        self._steady = bool(self.count.min() >= self.memory)

    def rms(self) -> np.ndarray:
        """(K,) RMS miss per lead (lead k at index k − 1); NaN where nothing was scored."""
        return np.where(self.count > 0, np.sqrt(self.ms), np.nan)


def rms_by_lead(predictor, z: np.ndarray, steps: int, first: int) -> np.ndarray:
    """(steps,) RMS over n ≥ ``first`` of e_k = ‖ẑ_{n+k|n} − z_{n+k}‖, k = 1 … ``steps``.

    ``predictor`` (:class:`rhmpc.predictors.base.Predictor`) is fed the samples ``z`` (n, d) in
    order, open loop; after each sample n with n + steps < len(z) and n ≥ ``first`` (its
    warm-up) it forecasts ``steps`` samples, scored against those that follow. Units: z's.
    """
    sq, count = np.zeros(steps), 0
    for n in range(len(z) - steps):
        predictor.update(z[n])
        if n >= first:
            e = predictor.predict(steps) - z[n + 1 : n + 1 + steps]
            sq += np.einsum("ij,ij->i", e, e)
            count += 1
    return np.sqrt(sq / count)
