"""Numbers in the command line's messages: significant digits, lengths, sizes and spans."""

from __future__ import annotations

import math

from rhmpc.io.limits import size_bytes, time_span

__all__ = ["fmt", "mm", "size_bytes", "time_span"]


def fmt(x: float, digits: int = 4) -> str:
    """``x`` to ``digits`` significant digits, without exponent or trailing zeros
    (``9.98667`` → ``9.987``, ``472.0`` → ``472``, ``257.069`` → ``257.1``)."""
    if not math.isfinite(x) or x == 0 or abs(x) >= 1e6:
        return f"{x:.{digits}g}"
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(x))))
    text = f"{x:.{decimals}f}"
    return text.rstrip("0").rstrip(".") if "." in text else text


def mm(value: float) -> str:
    """A length [mm] to the micrometre; with an exponent beyond a kilometre."""
    return f"{value:.3f}" if abs(value) < 1e6 else f"{value:.3g}"

