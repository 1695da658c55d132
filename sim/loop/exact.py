"""The exact reference of a study: the true future in place of a predictor's forecast.

"Exact reference information" (Tuna et al. 2013's tables): the MPC's points are the centred POI
truth of the ticks ahead, read from the simulation. It is a study device, not a predictor (no
controller can have it): the controller's library takes its points whole (``rhmpc_points``,
:class:`rhmpc.control.controller.Controller`), with no gate, interpolation or guard.
"""

from __future__ import annotations

import numpy as np

from rhmpc.positions import embed3, place_point

__all__ = ["ArrayTruth", "ExactReference", "windows"]


class ArrayTruth:
    """Centred POI truth from an array of positions at ticks 0 … n − 1 (n, d), and the
    ``center`` [m] it was centred on (zero by default)."""

    def __init__(self, truth: np.ndarray, center: np.ndarray | None = None) -> None:
        self.truth = np.array(truth, dtype=float).reshape(len(truth), -1)
        self.n_ticks, self.dim = self.truth.shape
        self.center = np.zeros(self.dim) if center is None else np.asarray(center, dtype=float)
        if not np.all(np.isfinite(self.truth).any(axis=0)):
            raise ValueError("the truth has no finite sample on some axis")

    def window(self, i0: int, i1: int) -> np.ndarray:
        return self.truth[i0:i1]


class ExactReference:
    """"Exact reference information" (Tuna et al.): the true future, no predictor.

    ``truth`` is the centred POI position at every tick of the run plus a horizon's margin: an
    array (n, d), or a truth read in windows (``window(i0, i1)``, ``n_ticks``, ``dim``), which
    keeps memory flat in run length. Gaps in it (NaN: dropouts of a recorded stream used as the
    truth) are bridged linearly between the finite ticks around them (constant before the first
    and after the last), so that the MPC is never handed NaN; the metrics still skip those
    ticks. Read in windows of ``window`` ticks, forward in time (reading backwards restarts from
    tick 0), the points are those of the whole array.
    """

    predictor = None
    center = np.zeros(3)

    def __init__(self, truth, horizon: int, window: int = 8192) -> None:
        self._truth = truth if hasattr(truth, "window") else ArrayTruth(truth)
        self.N, self._size = horizon, int(window)
        self.origin = np.zeros(3)
        self._restart()

    def bind(self, controller) -> None:
        """Feed ``controller``'s library (it asks for :meth:`points` as its ticks need them)."""

    def _restart(self) -> None:
        self._w0 = 0  # tick of self._points[0]
        self._points = np.empty((0, 3))
        self._last: list[tuple[int, float] | None] = [None] * self._truth.dim  # finite, before

    def _bridged(self, a: int, b: int) -> np.ndarray:
        """Truth of ticks a … b − 1 with its gaps bridged (windows are read in order)."""
        truth, n = self._truth, self._truth.n_ticks
        raw = np.array(truth.window(a, b), dtype=float)
        ticks = np.arange(a, b)
        for axis in range(raw.shape[1]):
            column = raw[:, axis]
            good = np.isfinite(column)
            previous = self._last[axis]
            if good.any():
                k = np.flatnonzero(good)[-1]
                self._last[axis] = (a + int(k), float(column[k]))
            if good.all():
                continue
            xs, fs = list(ticks[good]), list(column[good])
            if previous is not None:
                xs.insert(0, previous[0])
                fs.insert(0, previous[1])
            c = b
            while not good[-1] and c < n:  # the gap runs past the window: find its end
                ahead = np.asarray(truth.window(c, min(c + self._size, n)))[:, axis]
                found = np.flatnonzero(np.isfinite(ahead))
                if found.size:
                    xs.append(c + int(found[0]))
                    fs.append(float(ahead[found[0]]))
                    break
                c += self._size
            if not xs:
                raise ValueError("the exact reference has no finite sample on some axis")
            column[~good] = np.interp(ticks[~good], xs, fs)
        return raw

    def _cover(self, start: int, stop: int) -> np.ndarray:
        """Points of ticks start … stop − 1 (fewer at the end of the truth)."""
        if start < self._w0:
            self._restart()
        stop = min(stop, self._truth.n_ticks)
        end = self._w0 + self._points.shape[0]
        if stop > end:
            parts = [self._points[start - self._w0 :]] if start < end else []
            if start > end:  # skipped ahead: read (and drop) the ticks in between, in order
                while end < start:
                    self._bridged(end, min(end + self._size, start))
                    end = min(end + self._size, start)
            self._w0 = min(start, end)
            while end < stop:
                b = min(end + self._size, self._truth.n_ticks)
                parts.append(self.origin + embed3(self._bridged(end, b)))
                end = b
            self._points = np.concatenate(parts)
        return self._points

    def place(self, origin, center=(0.0, 0.0, 0.0)) -> None:
        """From now on :meth:`horizon` returns workspace points origin + E r_c (N, 3) [m], r_c
        the centred truth (``center``, the sensor's registration, is not read: no sample is)."""
        self.origin = place_point(origin)
        self._restart()

    def reset(self) -> None:
        pass

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        pass

    def horizon(self, tick: int) -> np.ndarray:
        """r_{tick+1} … r_{tick+N} in the workspace (N, 3) [m]."""
        return self.horizons(tick, 1)[0]

    def points(self, first: int, count: int) -> np.ndarray:
        """The points of ticks first … first + count − 1 (fewer at the end of the truth) [m]."""
        points = self._cover(first, first + count)
        return points[first - self._w0 : first - self._w0 + count]

    def horizons(self, tick: int, count: int) -> np.ndarray:
        """:meth:`horizon` of ticks tick … tick + count − 1 as one read-only (count, N, 3)
        array (:func:`windows`; a view of an array never changed)."""
        points = self._cover(tick + 1, tick + count + self.N)
        return windows(points, tick + 1 - self._w0, count, self.N)


def windows(points: np.ndarray, first: int, count: int, N: int) -> np.ndarray:
    """Rows ``first + k … first + k + N − 1`` of ``points`` (n, d) for k < count, as one
    read-only (count, N, d) array: a view of overlapping windows, or a copy when it runs past
    the last row (the last window is then repeated: a skipped refresh holds its points).
    ``points`` must hold at least N rows."""
    last = points.shape[0] - N
    if last < 0:
        raise ValueError(f"{points.shape[0]} points cannot make windows of {N}")
    if first + count - 1 > last or not points.flags.c_contiguous:
        starts = np.minimum(np.arange(first, first + count), last)
        out = points[starts[:, None] + np.arange(N)]
    else:
        row = points.strides[0]
        out = np.ndarray((count, N, points.shape[1]), points.dtype, points, first * row,
                         (row, row, points.strides[1]))
    out.flags.writeable = False
    return out
