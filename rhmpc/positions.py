"""Points in the workspace that the controller and the simulated world share: below both, so
that neither imports the other.

- :func:`embed3`, positions of a motion of d ≤ 3 axes in the 3-D workspace (a 1-D motion moves
  along x);
- :func:`place_point`, a point where a motion is placed, checked: 3 finite coordinates.

Units: metres.
"""

from __future__ import annotations

import numpy as np

__all__ = ["embed3", "place_point"]


def embed3(p: np.ndarray) -> np.ndarray:
    """(n, d) positions with d ≤ 3 as (n, 3), missing axes zero (1-D motion along x)."""
    p = np.atleast_2d(p)
    if p.shape[1] == 3:
        return p
    out = np.zeros((p.shape[0], 3))
    out[:, : p.shape[1]] = p
    return out


def place_point(origin, name: str = "origin") -> np.ndarray:
    """``origin`` as 3 finite coordinates [m] (a one-line ``ValueError`` naming ``name``
    otherwise)."""
    origin = np.array(origin, dtype=float).reshape(-1)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise ValueError(f"{name} must be 3 finite coordinates [m], got {origin!r}")
    return origin
