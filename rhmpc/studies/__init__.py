"""Studies built on runs: the controller bench, the Monte-Carlo prediction studies, and the
Table I/III comparison report.

Imports :mod:`rhmpc.control`, :mod:`rhmpc.experiment` and the layers below; never
:mod:`rhmpc.tuning` or :mod:`rhmpc.cli`.
"""
