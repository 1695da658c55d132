"""The predictors open loop, as ``rhmpc predict`` runs them: no robot, the forecasts scored
against what was measured.

=====================  ==================================================================
``recordings``         every predictor on a user's recordings (``--data``), each at the
                       recording's own rate; the literature's split
``plan``               its rules, its settings, and the plan of a track (the origins scored,
                       the fits, each predictor's step timed for the estimate)
``scoring``            one track scored: each predictor's errors per lead
``tracks``             the recordings it scores, one track per tracked point
``recordings_report``  its text tables and its figure
``studies``            the synthetic studies (``--study``): Yuen et al. 2008 §III-D and Tuna
                       et al. 2013 Fig. 8
``studies_report``     their text table and their figure
=====================  ==================================================================

Imports :mod:`rhmpc.experiment` (the plan of the fits before the run) and the layers below.
"""
