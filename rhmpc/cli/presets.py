"""Named operating points (``--preset NAME`` of ``simulate``, ``compare`` and ``tune``).

A preset is a set of ``--set`` overrides applied to the run's settings after the defaults and
the ``--config`` file, before the explicit options and ``--set``.

``tuna2013``
    The operating point of Tuna et al. (T-RO 2013), Tables I–III: controller weights that put
    the RMS control effort of the exact-reference run in Table I(b)'s range, 12–19 mN·m
    (11.7–18.9 published). Derivation (``rhmpc simulate --predictor exact --duration 30
    --seed 3 --set mpc.effort_weight=W`` on fixed-a2-top, paper 14.6 mN·m): W = 10 → 18.6,
    W = 50 → 13.5, W = 200 → 11.2 mN·m; W = 50 sits in the range, near the paper's value.
    Only the effort weight changes: the paper's Q, R and horizon are those of the default
    controller (25-ms horizon, 2 kHz). The sensor stays the default physical sonomicrometer
    with causal delivery (``--set sensor_settings.playback="offline"`` for the paper's
    playback of a prerecorded file).
"""

from __future__ import annotations

from typing import Any

from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig

#: Preset name → dotted settings it sets.
PRESETS: dict[str, dict[str, Any]] = {
    "tuna2013": {"mpc.effort_weight": 50.0},
}


def apply_preset(config: RunConfig, name: str | None) -> RunConfig:
    """``config`` with the preset's settings (``name`` None: unchanged).

    Raises
    ------
    UsageError
        Unknown preset (the message lists the valid ones).
    """
    if name is None:
        return config
    if name not in PRESETS:
        raise UsageError(f"unknown preset {name!r}; valid: {', '.join(PRESETS)}")
    return config.replace(**PRESETS[name])


def add_preset_option(p) -> None:
    """``--preset NAME`` on an argparse parser."""
    p.add_argument("--preset", choices=tuple(PRESETS), default=None,
                   help="a named operating point: tuna2013 = Tuna et al. 2013 Tables I-III "
                   "(exact-reference effort in Table I(b)'s 12-19 mN.m)")
