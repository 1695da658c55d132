"""A chunk's refresh slices run from the compiled control ticks, each on its own tick.

The closed loop runs a refresh in five slices on five ticks between the control ticks
(:meth:`sim.loop.closed_loop.OpenLoop.segments`). With the compiled controller on the compiled
plant, the control ticks run in C (:class:`sim.loop.ticks.CompiledTicks`); with the compiled
refresh (:class:`~rhmpc.control.compiled_reference.CompiledReference`) its slices can run from
there too: the loop plans a chunk's slices ahead (:meth:`~sim.loop.closed_loop.OpenLoop.plan`,
which slice on which tick, and each update's sample), and ``plan_points`` of
``rhmpc/control/refresh.c`` runs those due on a tick before the tick reads its points — the same
calls, in the same order, on the same ticks, timed at the same places as from Python, so a run
is the same to the bit, without a Python frame between them.
"""

from __future__ import annotations

import ctypes
import math

import numpy as np

__all__ = ["CompiledSlices"]

_i, _ll, _p = ctypes.c_int, ctypes.c_longlong, ctypes.c_void_p
#: The parts of a refresh (sim.loop.results.CHARGED): update, learning, forecast,
#: interpolation, bookkeeping.
PARTS = 5


class _Plan(ctypes.Structure):
    """``plan_t`` of rhmpc/control/refresh.c: a chunk's slices run from the control ticks."""

    _fields_ = [
        ("ref", _p), ("count", _i), ("next", _i), ("row", _p), ("part", _p), ("tick", _p),
        ("z", _p), ("d", _i), ("stamp", _p), ("fresh", _p), ("charged", _p), ("error", _i),
        ("m", _i),
        ("c0", _ll),
        ("buffer", _p * 2), ("live", _i), ("has_points", _i), ("hold", _p), ("h_tick", _p),
        ("h_points", _p), ("h_valid", _p), ("h_count", _i), ("h_cap", _i),
    ]


class CompiledSlices:
    """A chunk's refresh slices run by the compiled control ticks, each on its own tick.

    :meth:`load` takes the slices that :meth:`sim.loop.closed_loop.OpenLoop.segments` would run
    on the chunk's ticks (:meth:`~sim.loop.closed_loop.OpenLoop.plan`); ``function``
    (``plan_points`` of rhmpc/control/refresh.c) and ``state`` are what the control ticks call
    before each tick (:meth:`sim.plant.native.NativeTick.bind`): it runs the slices due on the
    tick, times each into ``charged[part, row]`` [ns], and returns the tick's N points — the
    calls, the order and the timing of the Python loop, without a Python frame between them.
    :meth:`finish` returns each refresh's points on its own tick and hands the last points back
    to the reference (:meth:`CompiledReference.horizons`).

    The points are written into two arrays of the chunk, in turn: the ticks read the live one
    while an interpolation writes the other. ``reference``: the
    :class:`~rhmpc.control.compiled_reference.CompiledReference` whose slices these are.
    """

    def __init__(self, reference, hold: np.ndarray) -> None:
        if reference._lib.plan_size() != ctypes.sizeof(_Plan):
            raise RuntimeError("plan_t of refresh.c and its ctypes mirror differ in size")
        self.reference = reference
        self.points = 3 * reference.N  # doubles of a tick's points
        self.function = ctypes.cast(reference._lib.plan_points, _p).value
        self._plan = _Plan(ref=reference._ptr.value)
        self.state = ctypes.addressof(self._plan)
        self._hold = np.ascontiguousarray(hold, dtype=float)
        if self._hold.shape != (reference.N, 3):
            raise ValueError(f"hold must be ({reference.N}, 3) points [m], got "
                             f"{self._hold.shape}")
        self._plan.hold = self._hold.ctypes.data
        self._keep: tuple = ()

    def load(self, c0: int, m: int, plan: dict, charged: np.ndarray) -> None:
        """The slices of ticks c0 … c0 + m − 1 (:meth:`~sim.loop.closed_loop.OpenLoop.plan`),
        timed into ``charged`` (parts, m) int64."""
        ref, p = self.reference, self._plan
        d = np.shape(plan["z"])[-1]
        if not ref._public.placed or ref._public.d not in (0, d) or not 1 <= d <= ref._dcap:
            raise ValueError(f"the compiled slices run a placed reference of {d} axes")
        ref._public.nz = d  # the samples' size while the predictor has not seen one
        arrays = {"row": np.intc, "part": np.intc, "tick": np.int64, "z": np.float64,
                  "stamp": np.float64, "fresh": np.uint8}
        plan = {k: np.ascontiguousarray(plan[k], dtype=t) for k, t in arrays.items()}
        count, row, part = plan["row"].shape[0], plan["row"], plan["part"]
        if plan["z"].shape != (count, d) or charged.shape != (PARTS, m) \
                or charged.dtype != np.int64 or not charged.flags.c_contiguous:
            raise ValueError(f"a plan of {count} slices needs z ({count}, {d}) and charged "
                             f"({PARTS}, {m}) int64, got {plan['z'].shape}, {charged.shape}")
        if any(plan[k].shape != (count,) for k in ("row", "part", "tick", "stamp", "fresh")) \
                or (count and (row[0] < 0 or row[-1] >= m or np.any(np.diff(row) < 0)
                               or part.min() < 0 or part.max() >= PARTS)):
            raise ValueError(f"a plan's slices run on rows 0 … {m - 1} in order, parts 0 … "
                             f"{PARTS - 1}, one entry of each array per slice")
        buffers = (np.empty((ref.span, 3)), np.empty((ref.span, 3)))
        if ref._points is not None:
            buffers[0][:] = ref._points
        interpolations = int(np.count_nonzero(plan["part"] == 3))
        h = (np.empty(interpolations, dtype=np.int64),
             np.empty((interpolations, ref.N, 3)), np.zeros(interpolations, dtype=np.uint8))
        p.count, p.next, p.m, p.c0, p.error = count, 0, m, c0, 0
        p.d = d
        p.row, p.part, p.tick, p.z, p.stamp, p.fresh = (
            plan[k].ctypes.data for k in ("row", "part", "tick", "z", "stamp", "fresh"))
        p.charged = charged.ctypes.data
        p.buffer[0], p.buffer[1] = buffers[0].ctypes.data, buffers[1].ctypes.data
        p.live, p.has_points = 0, ref._points is not None
        p.h_tick, p.h_points, p.h_valid = (a.ctypes.data for a in h)
        p.h_count, p.h_cap = 0, interpolations
        self._keep = (plan, charged, buffers, h)  # alive while the C side points at them

    def finish(self) -> list[tuple[int, np.ndarray | None]]:
        """Each refresh's ``(tick, points)`` (None before the first sample); the reference
        reads the last points from now on. Every slice loaded must have run."""
        p, ref = self._plan, self.reference
        if p.error:
            raise ValueError(ref.failure if p.error == -1 else ref.update_error(p.error, math.nan))
        if p.next != p.count:
            raise RuntimeError(f"{p.count - p.next} of the chunk's slices did not run")
        _, _, buffers, (ticks, points, valid) = self._keep
        if p.has_points:
            ref.adopt(buffers[p.live], buffers[1 - p.live])
        self._keep = ()
        return [(int(t), points[k] if valid[k] else None)
                for k, t in enumerate(ticks[: p.h_count])]
