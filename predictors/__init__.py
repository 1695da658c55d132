"""Heart-motion predictors, all on the `Predictor` contract of `rhmpc.predictors.base`.

``make_predictor(name, dt, **settings)`` builds one by name; ``PREDICTORS`` lists the online
ones, ``LEARNED`` those fitted before the run (:mod:`rhmpc.predictors.learned`), and
``family(name)`` tells which kind a name is.
"""

from rhmpc.predictors.base import Predictor
from rhmpc.predictors.registry import (
    LEARNED,
    PREDICTORS,
    family,
    make_predictor,
    needs_torch,
    predictor_names,
    settings_for,
)

__all__ = ["LEARNED", "PREDICTORS", "Predictor", "family", "make_predictor", "needs_torch",
           "predictor_names", "settings_for"]
