"""The host a run's ticks are timed on: the stalls it takes from a process that never waits."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

__all__ = ["STALL_FLOOR_NS", "host_stalls", "stall_line", "stall_summary"]


#: The shortest gap :func:`host_stalls` keeps [ns]: longer than any pause of the loop itself.
STALL_FLOOR_NS = 20_000


def host_stalls(seconds: float, floor_ns: int = STALL_FLOOR_NS,
                clock: Callable[[], int] = time.perf_counter_ns) -> np.ndarray:
    """The host's stalls: every gap of at least ``floor_ns`` between consecutive readings of
    ``clock`` [ns] in a loop that does nothing else for ``seconds``; returns the gaps [ns].

    A busy loop never waits, so a gap is time the host took from the process: an interrupt, the
    scheduler, the hypervisor. It is the measurement of the Linux kernel's hardware-latency
    tracer (``hwlat``, Documentation/trace/hwlat_detector.rst) and of jHiccup, here in the
    process and at the moment that a run's ticks are timed. A tick cannot be shorter than the
    stall that lands in it, so the longest stall bounds the longest tick a host can promise.
    """
    if not (seconds >= 0 and math.isfinite(seconds)):
        raise ValueError(f"seconds must be finite and >= 0, got {seconds!r}")
    gaps: list[int] = []
    last = clock()
    end = last + int(seconds * 1e9)
    while last < end:
        now = clock()
        if now - last >= floor_ns:
            gaps.append(now - last)
        last = now
    return np.asarray(gaps, dtype=np.int64)


def stall_summary(gaps_ns: np.ndarray, seconds: float, gain_us: float | None = None,
                  over_g: float = 50.0, floor_ns: int = STALL_FLOOR_NS) -> dict:
    """:func:`host_stalls`' gaps (of at least ``floor_ns``) as a document: how many, how many
    longer than ``over_g`` gain ticks, and the longest, in µs and (given ``gain_us``) in g."""
    gaps_us = np.asarray(gaps_ns, dtype=float) / 1e3
    longest = float(gaps_us.max()) if gaps_us.size else 0.0
    doc = {"seconds": float(seconds), "floor_us": floor_ns / 1e3, "stalls": int(gaps_us.size),
           "longest_us": longest}
    if gain_us is not None and gain_us > 0:
        doc["longest_g"] = longest / gain_us
        doc["over_g"] = float(over_g)  # the threshold of the count below [g]
        doc[f"over_{over_g:g}_g"] = int(np.count_nonzero(gaps_us > over_g * gain_us))
    return doc


def stall_line(stalls: dict) -> str:
    """What the host took from a busy loop (:func:`host_stalls`), in a line."""
    over = stalls.get("over_g")
    longest = f"{stalls['longest_us']:.0f} µs" + (
        f" = {stalls['longest_g']:.0f} g" if "longest_g" in stalls else "")
    return (f"a busy loop of {stalls['seconds']:g} s stalled {stalls['stalls']} times ≥ "
            f"{stalls['floor_us']:g} µs"
            + (f", {stalls[f'over_{over:g}_g']} of them > {over:g} g" if over else "")
            + f"; the longest {longest}, a floor under a tick's maximum on this host")
