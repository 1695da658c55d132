"""Real recordings shipped with the package, unchanged, each with its source and licence.

``--data NAME`` (``simulate``, ``compare``, ``predict``) reads a shipped recording by name when
no file of that name exists; the options the file does not state (its MATLAB variable, its rate,
its length unit) come from :data:`SHIPPED` unless given.

``hamlyn-phantom``
    Four points tracked at 25 frames/s in the Hamlyn Centre's stereo-endoscopic video of a
    beating-heart phantom, 30 s, millimetres (``hamlyn-phantom/README.md``: source, licence
    MIT, the point the literature predicts, its protocol and published results).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["SHIPPED", "Shipped", "resolve", "resolve_all"]

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Shipped:
    """A shipped recording: its file, how to read it, and the point the literature predicts.

    Attributes
    ----------
    path : Path
        The file.
    read : dict
        ``load_recording`` keywords the file does not state (``var``, ``rate`` [Hz], ``units``).
    poi : int | None
        The point of interest in a file of several tracked points (from 1), per its README.
    """

    path: Path
    read: dict = field(default_factory=dict)
    poi: int | None = None


#: Shipped recordings by name.
SHIPPED: dict[str, Shipped] = {
    "hamlyn-phantom": Shipped(HERE / "hamlyn-phantom" / "measuresPhantom.mat",
                              {"var": "measures", "rate": 25.0, "units": "mm"}, poi=4),
}


def resolve(data: str, read: dict) -> tuple[str, dict, int | None]:
    """``(path, read, poi)`` of ``data``: a file as it is (``poi`` None), or a shipped
    recording's name (when no such file exists) with its reading options under those given
    and the point the literature predicts."""
    shipped = SHIPPED.get(data)
    if shipped is None or Path(data).exists():
        return data, read, None
    return str(shipped.path), {**shipped.read, **read}, shipped.poi


def resolve_all(files: list[str], read: dict) -> tuple[list[str], dict, int | None]:
    """:func:`resolve` for several ``--data`` files, which share one way of reading: a shipped
    recording among other files must be read as they are (else ``ValueError``)."""
    resolved = [resolve(f, read) for f in files]
    reads = {tuple(sorted(r.items())) for _, r, _ in resolved}
    if len(reads) > 1:
        raise ValueError("a shipped recording is read with its own options (its variable, "
                         "rate and unit): give it alone, or with files read the same way")
    pois = {p for _, _, p in resolved}
    return [f for f, _, _ in resolved], resolved[0][1], pois.pop() if len(pois) == 1 else None
