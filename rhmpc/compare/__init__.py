"""``rhmpc compare``: predictors × scenarios (or recordings) in closed loop, in parallel, and
the table of their cells.

============  ==================================================================
``jobs``      a run per predictor × column (a scenario, a recording, a tracked point) × seed
``runs``      their execution in parallel, a split's open loops first; the JSON document
``estimate``  how long they take, said first, the time left kept as runs finish
``table``     the cells (the mean of the runs over seeds and its 95 % interval) and the
              comparison table, as text or CSV
``loop_gap``  a recording's closed loop beside the open loop on the same samples
============  ==================================================================

Imports :mod:`rhmpc.tuning` (its runner of processes that die with their parent, or a Dask
cluster), :mod:`rhmpc.openloop` and the layers below.
"""
