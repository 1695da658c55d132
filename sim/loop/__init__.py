"""The closed loop and what it leaves: streams in, running statistics and traces out.

=================  ==============================================================
``settings``       :class:`LoopSettings`: rate, horizon, refresh, gate, duration
``closed_loop``    :func:`run_closed_loop`: the open loop, its refresh slices tick by tick
``ticks``          the control ticks between two slices, from Python or in one C call
``streams``        sensor samples and POI truth read block by block (flat memory)
``results``        :class:`LoopResult`, the recorder of each chunk
``metrics``        running tracking statistics, tick histograms, heart-rate score
``trace``          the decimated trace and the per-tick NPZ file
=================  ==============================================================
"""

from sim.loop.closed_loop import poi_truth, run_closed_loop
from sim.loop.results import LoopResult, embed3
from sim.loop.settings import LoopSettings

__all__ = ["LoopResult", "LoopSettings", "embed3", "poi_truth", "run_closed_loop"]
