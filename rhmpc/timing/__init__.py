"""The instruments a run's timing is measured with, below the experiment that uses them.

=============  ==================================================================
``yardstick``  :class:`~rhmpc.timing.yardstick.GainTick`, the gain tick g every timing is
               stated in, timed in the same run as what it measures
``host``       the host's stalls in a busy loop (``--host-stalls``), a floor under a tick's
               maximum
=============  ==================================================================

Imports :mod:`rhmpc.control` (the MPC whose gain the yardstick applies) and the layers below.
"""
