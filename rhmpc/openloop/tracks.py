"""The recordings an open-loop study scores (:mod:`rhmpc.openloop.recordings`), as tracks.

A :class:`Track` is one point's samples; a file of several tracked points gives a track per
point (``--points``), or the point of interest's with the others beside it (``--poi``). Points
are numbered from 1, in the file's order (:mod:`rhmpc.sim.recordings.points`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc.sim.recordings import RecordedMotion, load_points
from rhmpc.sim.recordings.points import load_poi, pick_point

__all__ = ["Track", "data_tracks", "file_points", "load_tracks", "parse_points", "poi_tracks",
           "twelve_digits"]


@dataclass(frozen=True)
class Track:
    """One trajectory to score: a recording, or one tracked point of it.

    Attributes
    ----------
    label : str
        How tables and the JSON name it (``rec.csv``, ``rec.mat:p2``).
    t : ndarray, shape (n,)
        Sample times [s], increasing.
    z : ndarray, shape (n, d)
        Positions [m]; NaN = missing.
    file : str
        The file it came from.
    point : int | None
        Its point number in a file of several (from 1).
    others : ndarray, shape (n, P − 1, d), or None
        The other tracked points' positions at the same times [m] (NaN = missing), when ``z``
        is the point of interest of a file of several.
    """

    label: str
    t: np.ndarray
    z: np.ndarray
    file: str = ""
    point: int | None = None
    others: np.ndarray | None = None

    @property
    def period(self) -> float:
        """Δ, the median sample interval [s] (to 12 significant digits: timestamps written in
        decimal make 1/25 s ``0.03999999999999915``)."""
        return twelve_digits(float(np.median(np.diff(self.t))))

    def points(self) -> np.ndarray:
        """(n, P, d): the POI in row 0, then the other points."""
        if self.others is None:
            return self.z[:, None, :]
        return np.concatenate([self.z[:, None, :], self.others], axis=1)


def twelve_digits(x: float) -> float:
    """``x`` to 12 significant digits."""
    return float(f"{x:.12g}")


def parse_points(text: str | None) -> str | tuple[int, ...] | None:
    """``--points``: ``None`` (one-point files), ``"all"``, or point numbers from 1 (``"1,3"``)."""
    if text is None or text.strip().lower() == "all":
        return None if text is None else "all"
    try:
        numbers = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        numbers = ()
    if not numbers or min(numbers) < 1:
        raise ValueError(f"--points {text!r}: expected all or point numbers from 1 (e.g. 1,3)")
    return numbers


def _labels(files: Sequence[str]) -> list[str]:
    """A label per file: its name, or the path as given where two names collide."""
    names = [Path(f).name for f in files]
    return [n if names.count(n) == 1 else str(f) for n, f in zip(names, files, strict=True)]


def file_points(files: Sequence[str], points, read: dict) -> list[list[tuple[str, str, int | None,
                                                                             RecordedMotion]]]:
    """Per file, its (label, file, point, recording) to score: every point or the chosen ones
    (``points`` from :func:`parse_points`); ``point`` is ``None`` in a one-point file.

    Raises
    ------
    ValueError
        A file that cannot be read, a point it lacks, or several points and no ``points``.
    """
    out = []
    for label, f in zip(_labels(files), files, strict=True):
        recordings = load_points(f, **read)
        several = len(recordings) > 1
        if several and points is None:
            raise ValueError(f"{f}: holds {len(recordings)} tracked points; choose them with "
                             "--points all (or --points 1,3, numbered from 1)")
        chosen = range(1, len(recordings) + 1) if points in (None, "all") else points
        out.append([(f"{label}:p{k}" if several else label, f, k if several else None,
                     pick_point(f, recordings, k)) for k in chosen])
    return out


def load_tracks(files: Sequence[str], points, read: dict) -> list[Track | list[Track]]:
    """The tracks of ``files`` for :func:`run_open_loop`: a file of several points gives the
    list of its points (scored with their mean), a one-point file its track."""
    out: list[Track | list[Track]] = []
    for group in file_points(files, points, read):
        tracks = [Track(label, rec.t, rec.z, f, k) for label, f, k, rec in group]
        out.append(tracks if group[0][2] is not None else tracks[0])
    return out


def poi_tracks(files: Sequence[str], poi: int, read: dict) -> list[Track]:
    """Per file, the track of its point ``poi`` (from 1) with the other points as ``others``
    (file order); a one-point file has ``poi`` 1 and no others."""
    out = []
    for label, f in zip(_labels(files), files, strict=True):
        rec, others = load_poi(f, poi, **read)
        several = others is not None
        out.append(Track(f"{label}:p{poi}" if several else label, rec.t, rec.z, f,
                         poi if several else None, others))
    return out


def data_tracks(data: Sequence[str], options: dict, points: str | None = None,
                poi: int | None = None, train: Sequence[str] = ()
                ) -> tuple[list[Track | list[Track]], Callable[[float], list] | None]:
    """The tracks an open-loop study scores, and the training recordings as a function of the
    sampling period (None without ``train``).

    Parameters
    ----------
    data : sequence of str
        The recordings: files, or the names of shipped ones
        (:func:`rhmpc.sim.recordings.shipped.resolve_all`).
    options : dict
        How to read them (``load_recording``'s keywords given on the command line).
    points : str or None
        ``all`` or ``N[,N...]``: each point scored on its own (:func:`load_tracks`).
    poi : int or None
        The point of interest, with the others beside it (:func:`poi_tracks`); by default a
        shipped recording's own.
    train : sequence of str
        Recordings to fit the fitted predictors on, read as ``data``.

    Raises
    ------
    ValueError
        A file that cannot be read, a point it does not hold.
    """
    from functools import partial

    from rhmpc.sim.recordings import training_series
    from rhmpc.sim.recordings.formats import check_source
    from rhmpc.sim.recordings.shipped import resolve_all

    files, read, own = resolve_all(data, options)
    if poi is None and points is None:
        poi = own
    tracks = poi_tracks(files, poi, read) if poi is not None else load_tracks(
        files, parse_points(points), read)
    for f in train:  # each a file (or a bag's folder) the one reader takes
        check_source(f)
    return tracks, partial(training_series, list(train), poi, read) if train else None
