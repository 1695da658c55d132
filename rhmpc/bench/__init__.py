"""``rhmpc bench``: the MPC's tick timed against the gain tick and an exact active-set solve.

============  ================================================================
``ticks``     :func:`~rhmpc.bench.ticks.run_bench`: the timed ticks and their accuracy
``exported``  the exported controller's every tick, and its torques against the Python one's
``report``    the text table of a bench's result
============  ================================================================

Imports :mod:`rhmpc.experiment`, :mod:`rhmpc.timing` and the layers below.
"""
