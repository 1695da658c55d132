"""Heart-motion predictors, all on the `Predictor` contract of `predictors.base`.

``make_predictor(name, dt, **settings)`` builds one by name; ``PREDICTORS`` lists them.
"""

from predictors.base import Predictor
from predictors.registry import PREDICTORS, make_predictor, settings_for

__all__ = ["PREDICTORS", "Predictor", "make_predictor", "settings_for"]
