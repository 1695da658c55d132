"""Studies built on runs: the controller bench, the Monte-Carlo prediction studies, and the
comparison with Tuna et al.'s Tables I–III and its findings.

Imports :mod:`rhmpc.control`, :mod:`rhmpc.experiment` and the layers below; never
:mod:`rhmpc.tuning` or :mod:`rhmpc.cli`.
"""
