"""Where the sonomicrometer's crystals are: the reference base and the POI crystal."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: The golden angle [deg]: successive crystals this far apart round the circle never line up
#: symmetrically (the paper's base is "asymmetric"; its angles are not published).
GOLDEN_ANGLE_DEG = 180.0 * (3.0 - math.sqrt(5.0))


@dataclass(frozen=True)
class CrystalArray:
    """The reference crystals on a circle in the base's plane z = 0, the POI crystal above it.

    Defaults from Tuna et al. (2013) §III-A: "five other crystals were asymmetrically mounted
    on a rigid plastic base of diameter 60 mm, on a circle of diameter 50 mm", the base in a
    balloon of glycerine solution against the heart. The angles are not published: crystal k
    sits at k × :data:`GOLDEN_ANGLE_DEG` (the golden angle, asymmetric for any count). The POI
    crystal's distance from the base (``standoff``) is not published either: 30 mm is an
    assumption (a balloon a few centimetres thick; every line of sight then lies within 40° of
    the base's axis).

    Attributes
    ----------
    count : int
        Number of reference crystals (≥ 4: three ranges fix a point up to a mirror image,
        the fourth makes the fix over-determined, as the instrument's least squares needs).
    diameter : float
        Diameter of the circle the reference crystals sit on [m] (50 mm).
    standoff : float
        Nominal distance of the POI crystal from the base's plane, on its axis [m] (30 mm).
    angles : tuple of float or None
        Angular positions of the crystals on the circle [deg]; None: k ×
        :data:`GOLDEN_ANGLE_DEG`.
    """

    count: int = 5
    diameter: float = 50e-3
    standoff: float = 30e-3
    angles: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if isinstance(self.count, bool) or int(self.count) != self.count or self.count < 4:
            raise ValueError(f"sonomicrometry needs ≥ 4 reference crystals, got {self.count}")
        for name in ("diameter", "standoff"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"crystal {name} must be a finite length > 0 [m], got {value}")
        if self.angles is not None:
            if len(self.angles) != self.count:
                raise ValueError(f"crystal angles: {len(self.angles)} given for {self.count} "
                                 "crystals")
            if not all(math.isfinite(a) for a in self.angles):
                raise ValueError("crystal angles must be finite [deg]")

    def positions(self) -> np.ndarray:
        """Reference crystal positions b_i = (R cos α_i, R sin α_i, 0) [m], shape (count, 3)."""
        alpha = np.deg2rad(self.angles if self.angles is not None
                           else GOLDEN_ANGLE_DEG * np.arange(self.count))
        r = self.diameter / 2.0
        return np.column_stack([r * np.cos(alpha), r * np.sin(alpha), np.zeros(alpha.size)])

    def poi(self) -> np.ndarray:
        """Nominal POI crystal position (0, 0, standoff) [m]."""
        return np.array([0.0, 0.0, self.standoff])
