"""What each fault injected into a run did to it: the ticks where the loop reads its counters
(:func:`fault_marks`, ``run_closed_loop(marks=…)``) and one record per fault from the result's
segments (:func:`fault_report`): what changed during it and in the ``after_s`` seconds after it.
The faults themselves act in the loop (:mod:`rhmpc.sim.loop.faults`,
:mod:`rhmpc.sim.sensors.faults`).
"""

from __future__ import annotations

import numpy as np

from rhmpc.sim.loop.clock import arrival_tick

__all__ = ["REPORTED", "fault_marks", "fault_report"]

#: The counts a fault's record states (the differences over its windows), and how the run's
#: summary names them.
REPORTED = {"missing": "samples missing", "outliers_rejected": "rejected",
            "gate_unlocked": "gate unlocked", "retracted": "retracted",
            "reference_guard": "reference guard", "encoder_held_ticks": "encoder ticks held",
            "qp_failures": "QP failures", "fallback_plan": "plan", "fallback_lq": "lq",
            "fallback_brake": "brake", "fallback_zero": "zero",
            "saturated_ticks": "saturated ticks"}


def _windows(fault, after_s: float, duration: float) -> tuple[tuple[float, float], ...]:
    """(during, after) of ``fault`` [s], clipped to the run: after is empty for one that lasts
    to the end."""
    end = min(fault.end_s, duration)
    return (fault.start_s, end), (end, min(end + after_s, duration))


def fault_marks(faults, after_s: float, Ts: float, duration: float) -> list[int]:
    """The ticks at which each fault's windows begin and end (:func:`_windows`)."""
    marks = set()
    for fault in faults:
        for a, b in _windows(fault, after_s, duration):
            marks.update((arrival_tick(a, Ts), arrival_tick(b, Ts)))
    return sorted(marks)


def _span(segments, a: int, b: int) -> dict:
    """Largest error [mm], envelope and counts over ticks a … b − 1 (segments tile the run,
    their edges include a and b)."""
    inside = [s for s in segments if a <= s["ticks"][0] and s["ticks"][1] <= b]
    if not inside:
        return {}
    errors = [s["max_error_m"] for s in inside if np.isfinite(s["max_error_m"])]
    start = next((s["counts"] for s in reversed(segments) if s["ticks"][1] <= a), {})
    end = inside[-1]["counts"]
    return {
        "max_error_mm": 1e3 * max(errors) if errors else None,
        "position_margin_rad": min(s["envelope"]["position_margin_rad"] for s in inside),
        "speed_margin_rad_s": min(s["envelope"]["speed_margin_rad_s"] for s in inside),
        "envelope_held": all(s["envelope"]["held"] for s in inside),
        "counts": {k: end.get(k, 0) - start.get(k, 0) for k in REPORTED},
    }


def fault_report(specs, faults, segments, after_s: float, Ts: float,
                 duration: float) -> list[dict]:
    """One record per fault: its form, kind, window [s] and ``after_s``, and for ``during`` and
    ``after`` (the ``after_s`` seconds that follow it, None for a fault to the end of the run)
    the largest error [mm], the joint envelope and the counts of :data:`REPORTED` over the
    window. A sample the gate rejected is counted in ``outliers_rejected`` alone (the predictor
    counts it missing too)."""
    out = []
    for spec, fault in zip(specs, faults, strict=True):
        during, after = _windows(fault, after_s, duration)
        record = {"fault": spec, "kind": fault.kind, "start_s": fault.start_s,
                  "end_s": during[1], "after_s": after_s}
        for name, (a, b) in (("during", during), ("after", after)):
            span = _span(segments, arrival_tick(a, Ts), arrival_tick(b, Ts))
            if span:
                counts = span["counts"]
                counts["missing"] -= counts["outliers_rejected"]
            record[name] = span or None
        out.append(record)
    return out
