"""The closed loop and what it leaves: streams in, running statistics and traces out.

=================  ==============================================================
``settings``       :class:`LoopSettings`: control period, refresh clock, duration, placement
``clock``          when the reference refreshes: every ``downsample`` ticks, or on each sample
``closed_loop``    :func:`run_closed_loop`: refreshes, the controller's step, the plant's step
``streams``        the newest sample by a time, the POI truth by window (flat memory)
``results``        :class:`LoopResult`, the recorder of each chunk
``metrics``        running tracking statistics, tick histograms, heart-rate score
``trace``          the decimated trace and the per-tick NPZ file
``faults``         faults injected into the encoders, each fault's report
=================  ==============================================================
"""

from __future__ import annotations

import importlib

#: Each name of the package and its module, loaded when first asked for (the settings alone
#: load without the loop).
_EXPORTS = {"LoopResult": "results", "LoopSettings": "settings", "poi_truth": "closed_loop",
            "run_closed_loop": "closed_loop"}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
