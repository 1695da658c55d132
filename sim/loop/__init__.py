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

from rhmpc.sim.loop.closed_loop import poi_truth, run_closed_loop
from rhmpc.sim.loop.results import LoopResult
from rhmpc.sim.loop.settings import LoopSettings

__all__ = ["LoopResult", "LoopSettings", "poi_truth", "run_closed_loop"]
