"""Incremental joint encoders: quantised joint angles."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Encoder:
    """Incremental joint encoder: q̂ = Δ·round(q/Δ), Δ = 2π/counts_per_rev (or floor).

    Attributes
    ----------
    counts_per_rev : int
        Counts per revolution after quadrature decoding (4 × 1024 lines).
    mode : str
        ``"round"`` (error in ±Δ/2, unbiased) or ``"floor"`` (counter truncation, error in
        [0, Δ)).
    """

    counts_per_rev: int = 4 * 1024
    mode: str = "round"

    def __post_init__(self) -> None:
        if self.counts_per_rev <= 0:
            raise ValueError("counts_per_rev must be positive")
        if self.mode not in ("round", "floor"):
            raise ValueError("encoder mode must be 'round' or 'floor'")

    @property
    def resolution(self) -> float:
        """Δ = 2π / counts_per_rev [rad]."""
        return 2 * np.pi / self.counts_per_rev

    def counts(self, q: np.ndarray) -> np.ndarray:
        """Integer counts for joint angles ``q`` [rad]."""
        x = np.asarray(q, dtype=float) / self.resolution
        return (np.round(x) if self.mode == "round" else np.floor(x)).astype(np.int64)

    def quantize(self, q: float | np.ndarray) -> np.ndarray:
        """Quantised joint angles q̂ [rad], same shape as ``q``."""
        return self.counts(q) * self.resolution
