"""Steps 4–6 of the closed loop: the control ticks between two refresh slices.

Each tick: the encoders and the observer give x̂ (``sense``), the controller the MPC torque,
the cancellation the commanded torque (``actuate``), the plant one tick (``advance``); the
tick is timed from the encoder reading to the commanded torque, by part. :func:`run_ticks`
calls them one at a time from Python; :class:`CompiledTicks`, for a compiled controller on the
compiled plant, runs all the ticks between two slices in one C call, with the same functions in
the same order, hence the same results (:func:`compiled_ticks` chooses). The ticks come in the
segments of :meth:`sim.loop.closed_loop.OpenLoop.segments`, whose slices run as they are
iterated; rows are written into a chunk's records (:meth:`sim.loop.results.Recorder.start_chunk`).
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from sim.loop.metrics import warm_ns
from sim.loop.results import YARDSTICK_EVERY, YARDSTICK_PHASE
from sim.loop.settings import LoopSettings

clock = time.perf_counter_ns
#: Ticks between two calls of ``progress``.
PROGRESS = 2000


def compiled_ticks(controller, side, settings: LoopSettings) -> tuple[CompiledTicks | None, str]:
    """The compiled ticks where the controller and the robot's side are both compiled and
    ``settings.compiled_ticks`` allows them, and the loop's name for the run's document:
    ``"compiled"``, or ``"python"`` with the reason."""
    control = getattr(controller, "compiled_tick", None)
    if not settings.compiled_ticks:
        why = "loop.compiled_ticks = false"
    elif control is None:
        why = "the controller has no compiled tick"
    elif not hasattr(side, "run_ticks"):
        why = f"the plant runs on {side.dynamics}"
    elif control.dims != (settings.horizon, 2 * side.nv, side.nv, 3):
        why = (f"the controller's (N, nx, nu, ny) {control.dims} are not the loop's "
               f"{(settings.horizon, 2 * side.nv, side.nv, 3)}")
    else:
        return CompiledTicks(side, control), "compiled"
    return None, f"python ({why})"


def run_ticks(side, controller, c0: int, segments: Iterator[tuple[int, np.ndarray, int]],
              log: dict, yardstick=None, progress=None) -> None:
    """Steps 4–6 in Python, for the ticks of ``segments`` (:meth:`OpenLoop.segments`, whose
    refresh slices run as it is iterated), written into row k = i − c0 of the chunk's records
    ``log`` (:meth:`~sim.loop.results.Recorder.start_chunk`).

    ``side`` is the robot's side of the tick (:mod:`sim.plant.tick`). The tick's time is from
    the encoder reading to the commanded torque (its parts: ``sense``, ``controller``,
    ``actuate``), plus the slices charged to it. ``yardstick(x̂, r, u_{−1})`` is timed on every
    64th tick with the tick's own inputs (the least of three calls,
    :func:`sim.loop.metrics.warm_ns`).
    """
    sense, actuate, advance, step = side.sense, side.actuate, side.advance, controller.step
    q_log, tau_mpc_log, tau_log = log["q"], log["tau_mpc"], log["tau"]
    parts, ref0, yard_ns = log["parts_ns"], log["ref0"], log["yardstick_ns"]
    u_prev = log["u_prev"]
    for i0, refs, _ in segments:
        k0 = i0 - c0
        ref0[k0 : k0 + len(refs)] = refs[:, 0]
        for k, ref in enumerate(refs, k0):
            t_start = clock()
            x_hat = sense()
            t_sensed = clock()
            u = step(x_hat, ref)
            t_stepped = clock()
            tau = actuate(u)
            t_end = clock()
            parts[k] = (t_sensed - t_start, t_stepped - t_sensed, t_end - t_stepped)
            if (yardstick is not None and (c0 + k) % YARDSTICK_EVERY == YARDSTICK_PHASE
                    and u_prev is not None):
                yard_ns.append(warm_ns(yardstick, x_hat, ref, u_prev))
            u_prev = u
            tau_mpc_log[k] = u
            tau_log[k] = tau
            advance()
            q_log[k] = side.q
        _report(progress, i0, i0 + len(refs))
    log["u_prev"] = u_prev


class CompiledTicks:
    """Steps 4–6 in C: the control ticks between two refresh slices in one call.

    A compiled controller (its ``compiled_tick``, :class:`rhmpc.control.export.CompiledTick`)
    on the compiled robot side (:meth:`sim.plant.native.NativeTick.run_ticks`): the same C
    functions in the same order as :func:`run_ticks` calls them through Python, hence the same
    results, timed at the same places; what is gone is the interpreter between them, as in a
    deployed controller. The refresh slices still run in Python, each on its tick, between
    two calls. The yardstick is timed after each call, on the inputs the C ticks kept.
    """

    def __init__(self, side, control) -> None:
        self.side, self.control = side, control
        self.points = (control.dims[0], 3)  # a tick's reference points

    def run(self, c0: int, segments: Iterator[tuple[int, np.ndarray, int]], log: dict,
            yardstick=None, progress=None) -> None:
        """As :func:`run_ticks`, for the chunk whose first tick is c0."""
        phase = (YARDSTICK_PHASE - c0) % YARDSTICK_EVERY
        self.side.bind(self.control, log, YARDSTICK_EVERY, phase)
        first = True
        for i0, refs, address in segments:
            self._check(refs)
            u_first = self.control.take_u_prev() if first else None
            self.side.run_ticks(i0 - c0, len(refs), address, refs.strides[0] // 8,
                                None if u_first is None else u_first.ctypes.data)
            first = False
            if yardstick is not None:
                self._yardstick(yardstick, log, i0 - c0, i0 - c0 + len(refs), phase,
                                lambda k, k0=i0 - c0, refs=refs: refs[k - k0])
            _report(progress, i0, i0 + len(refs))
        log["u_prev"] = log["tau_mpc"][-1].copy()

    def run_planned(self, c0: int, c1: int, plan: dict, slices, log: dict, yardstick=None,
                    progress=None) -> list:
        """Ticks c0 … c1 − 1 with their refresh slices in C too: ``slices``
        (:class:`rhmpc.control.compiled_reference.CompiledSlices`) runs the chunk's ``plan``
        (:meth:`~sim.loop.closed_loop.OpenLoop.plan`) from the ticks, each slice on its own tick
        before the tick's points are read, timed into ``log["charged"]``. One C call per
        :data:`PROGRESS` ticks; the yardstick is timed after the chunk on the kept x̂ and
        points. Returns each refresh's ``(tick, points)``."""
        m, every = c1 - c0, YARDSTICK_EVERY
        phase = (YARDSTICK_PHASE - c0) % every
        log["ref_saved"] = np.empty((m // every + 1, slices.points))
        slices.load(c0, m, plan, log["charged"])
        self.side.bind(self.control, log, every, phase, slices)
        u_first = self.control.take_u_prev()
        k0 = 0
        while k0 < m:
            k1 = min((c0 + k0) // PROGRESS * PROGRESS + PROGRESS - c0, m)
            self.side.run_ticks(k0, k1 - k0, 0, 0,
                                None if u_first is None else u_first.ctypes.data)
            u_first = None
            _report(progress, c0 + k0, c0 + k1)
            k0 = k1
        horizons = slices.finish()
        if yardstick is not None:
            saved = log["ref_saved"].reshape(-1, *self.points)
            self._yardstick(yardstick, log, 0, m, phase, lambda k: saved[k // every])
        log["u_prev"] = log["tau_mpc"][-1].copy()
        return horizons

    def _check(self, refs: np.ndarray) -> None:
        """The C ticks read each tick's points as N × 3 C-ordered doubles: anything else is an
        error here, not memory read amiss."""
        if refs.dtype != np.float64 or refs.shape[1:] != self.points \
                or refs.strides[1:] != (24, 8):
            raise ValueError(f"the compiled ticks read {self.points} C-ordered float64 points a "
                             f"tick, got {refs.dtype} {refs.shape[1:]}, strides "
                             f"{refs.strides[1:]}")

    def _yardstick(self, yardstick, log: dict, k0: int, k1: int, phase: int, points) -> None:
        """The yardstick on the kept x̂ of rows k0 … k1 − 1, their points (``points(k)``) and
        u_{−1}."""
        every, tau_mpc = YARDSTICK_EVERY, log["tau_mpc"]
        for k in range(k0 + (phase - k0) % every, k1, every):
            u_prev = tau_mpc[k - 1] if k > 0 else log["u_prev"]
            if u_prev is not None:
                x_hat = log["x_saved"][k // every]
                log["yardstick_ns"].append(warm_ns(yardstick, x_hat, points(k), u_prev))


def _report(progress, i0: int, i1: int) -> None:
    """``progress(done)`` at each multiple of :data:`PROGRESS` ticks in (i0, i1], once, with
    the last."""
    if progress is not None and i1 // PROGRESS > i0 // PROGRESS:
        progress(i1 // PROGRESS * PROGRESS)
