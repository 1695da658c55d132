"""Predictors fitted before the run, then online on the `Predictor` contract.

``ridge`` and ``st-ridge`` (:mod:`rhmpc.predictors.learned.ridge`) need NumPy only; the neural
networks (:mod:`rhmpc.predictors.learned.neural`: LSTM, GRU, TCN) need PyTorch, the optional extra
``pip install "rhmpc[learned]"``, and are imported only when one is asked for.
"""
