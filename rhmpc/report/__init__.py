"""One closed-loop run's report: what ``rhmpc simulate`` prints and writes about its run.

================  ================================================================
``summary``       the text summary after a run (:func:`~rhmpc.report.summary.format_summary`)
``figures``       ``--plot``: the dashboard (every axis, the error and the torques; a zoom and
                  a detail)
``paper_figure``  ``--plot --figure paper``: one column wide, its numbers the summary's
``replay``        ``--view``: the 3-D replay, one HTML page that opens offline (its scene in
                  ``replay_scene``, its page and player in ``templates/``)
``matlab``        ``--out FILE.mat``: the summary and the trace for MATLAB
================  ================================================================

Imports :mod:`rhmpc.experiment` and the layers below.
"""
