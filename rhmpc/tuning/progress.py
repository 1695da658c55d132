"""Progress on stderr and times in words, for the long commands (``rhmpc tune``, ``rhmpc compare``).

- :func:`progress_bar` — a tqdm bar on stderr with an ETA, drawn at once (also when stderr is
  a file), or a silent one for ``--quiet``;
- :class:`Heartbeat` — redraws a bar between its updates, so that its elapsed time moves while
  long runs are in flight;
- :func:`format_duration` — ``4.7 s``, ``12 min 5 s``, ``3 h 12 min``, ``31 years``;
- :func:`speed_phrase` — ``14× faster than real time`` / ``2.3× slower than real time``.
"""

from __future__ import annotations

import sys
import time
from typing import Any

__all__ = ["Heartbeat", "format_duration", "note", "progress_bar", "speed_phrase"]

#: Seconds between redraws of a bar on a terminal, and in a file (a log grows line by line).
REDRAW_TTY_S = 1.0
REDRAW_FILE_S = 10.0

_MINUTE, _HOUR, _DAY, _YEAR = 60.0, 3600.0, 86400.0, 365.25 * 86400.0


def _is_tty(stream: Any) -> bool:
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # a closed stream
        return False


def redraw_interval(stream: Any = None) -> float:
    """Seconds between redraws of a bar on ``stream`` (default stderr) [s]."""
    return REDRAW_TTY_S if _is_tty(stream or sys.stderr) else REDRAW_FILE_S


def progress_bar(total: int, unit: str, desc: str, quiet: bool = False,
                 bar_format: str | None = None):
    """A tqdm bar on stderr with an ETA, drawn at once; disabled when ``quiet``.

    Parameters
    ----------
    total : int
        Units of work (runs, evaluations).
    unit : str
        Their name (``"run"``, ``"eval"``).
    desc : str
        The bar's label.
    quiet : bool
        No output at all (``--quiet``).
    bar_format : str or None
        tqdm's ``bar_format`` (e.g. a time left of the caller's own in ``{postfix}``).

    Returns
    -------
    tqdm.tqdm
        The bar; ``update(1)`` per finished unit, ``write(text)`` for a line above it.
    """
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, disable=quiet,
                dynamic_ncols=True, smoothing=0.1, mininterval=redraw_interval(),
                bar_format=bar_format)


def note(text: str, quiet: bool = False) -> None:
    """One line of progress information on stderr (nothing when ``quiet``), flushed."""
    if not quiet:
        print(text, file=sys.stderr, flush=True)


class Heartbeat:
    """Redraws a tqdm bar at most every :func:`redraw_interval` seconds.

    Call it whenever the caller wakes up (e.g. after a ``wait`` with a timeout): the bar's
    elapsed time and ETA move even while no unit finishes.

    Parameters
    ----------
    bar : tqdm.tqdm
        The bar to redraw (a disabled bar is left alone).
    """

    def __init__(self, bar) -> None:
        self.bar = bar
        self.interval = redraw_interval()
        self.last = time.monotonic()

    def __call__(self) -> None:
        now = time.monotonic()
        if not getattr(self.bar, "disable", False) and now - self.last >= self.interval:
            self.bar.refresh()
            self.last = now


def format_duration(seconds: float) -> str:
    """A duration rounded for a reader: ``0.46 s``, ``4.7 s``, ``8 s``, ``47 s``, ``12 min 5 s``,
    ``3 h 12 min``, ``4.2 days``, ``31 years``.

    Parameters
    ----------
    seconds : float
        The duration [s] (non-finite: ``"?"``).

    Returns
    -------
    str
        Two or three significant figures, in the largest unit that keeps them whole.
    """
    s = float(seconds)
    if s != s or s in (float("inf"), float("-inf")):
        return "?"
    if s < 1.0:
        return f"{s:.2g} s"
    if s < 9.95:
        return f"{s:.1f}".removesuffix(".0") + " s"
    if s < _MINUTE - 0.5:
        return f"{s:.0f} s"
    if s < _HOUR - 30:
        m, r = divmod(round(s), 60)
        return f"{m} min {r} s" if r else f"{m} min"
    if s < 2 * _DAY - 1800:
        h, m = divmod(round(s / 60), 60)
        return f"{h} h {m} min" if m else f"{h} h"
    if s < _YEAR:
        return f"{_sig(s / _DAY)} days"
    return f"{_sig(s / _YEAR)} years"


def _sig(x: float) -> str:
    """Two significant figures, without an exponent below 1e6."""
    if x >= 1e6:
        return f"{x:.1e}"
    if x >= 10:
        return f"{round(x, -int(f'{x:e}'.split('e')[1]) + 1):.0f}"
    return f"{x:.2g}"


def speed_phrase(simulated_s: float, wall_s: float) -> str:
    """How a run's speed compares with real time, in words.

    Parameters
    ----------
    simulated_s : float
        Simulated time [s].
    wall_s : float
        Wall time it took [s].

    Returns
    -------
    str
        ``"14× faster than real time"``, ``"2.3× slower than real time"``, ``"about real
        time"`` (within 5 %), or ``"speed unknown"`` when a time is not positive.
    """
    if not (simulated_s > 0 and wall_s > 0):
        return "speed unknown"
    factor = simulated_s / wall_s
    if 1 / 1.05 <= factor <= 1.05:
        return "about real time"
    if factor > 1:
        return f"{_sig(factor)}× faster than real time"
    return f"{_sig(1 / factor)}× slower than real time"
