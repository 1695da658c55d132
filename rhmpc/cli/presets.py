"""``--preset NAME``: the named operating points of :mod:`rhmpc.experiment.presets`."""

from __future__ import annotations

from rhmpc.experiment.presets import PRESETS


def add_preset_option(p) -> None:
    """``--preset NAME`` on an argparse parser."""
    p.add_argument("--preset", choices=tuple(PRESETS), default=None,
                   help="a named operating point: tuna2013 = Tuna et al. 2013 Table I (their "
                   "simulation: the linear model as the plant, effort in Table I(b)'s range); "
                   "hardware = the hardware-like plant; tuna2013-hardware = Tables II-III "
                   "(hardware plant, error from the encoders)")
