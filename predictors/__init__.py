"""Heart-motion predictors, all on the `Predictor` contract of `predictors.base`."""
