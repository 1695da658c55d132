"""Neural predictors: LSTM, GRU and TCN forecasters of the POI, fitted before the run
(PyTorch), then online on the `Predictor` contract.

Names: ``lstm``, ``gru``, ``tcn`` read the POI only; ``st-lstm``, ``st-gru``, ``st-tcn`` read
every tracked point (the spatio-temporal models of Zhang et al. 2022 and Li et al. 2022,
which feed the other points' past as well as the POI's). The architectures and training
settings are the papers' (:mod:`predictors.learned.settings`).

Fitting.  Every channel is z-scored with its mean and standard deviation over the training
series; a missing input takes the channel's previous value. For each lead k (or all at once,
``heads="joint"``) and each of the ``ensemble`` seeds, a network is trained on the sequences
(:func:`predictors.learned.networks.train`), the target at instant t the z-scored POI at
t + k. Seeds: ``numpy.random.SeedSequence(seed)`` spawns one per network.

Online.  The networks run one step per sample with NumPy, from a zero state as in training:
recurrent ones through their cells (the LSTM of Hochreiter & Schmidhuber 1997 with a forget
gate, the GRU of Cho et al. 2014, in PyTorch's gate layout), a TCN through its convolutions'
queues of past inputs (zeros before the first sample: the training's padding). The forecast
is the mean of the ensemble, ẑ_{n+k} = μ + σ ⊙ mean_e f_{k,e}.
"""

from __future__ import annotations

import numpy as np
import torch

from predictors.learned.fitted import FittedPredictor, settings_from_json, settings_to_json
from predictors.learned.networks import build, train
from predictors.learned.series import channel_stats, fill_forward
from predictors.learned.settings import (
    GRU_PRESETS,
    LSTM_PRESETS,
    TCN_PRESETS,
    NetworkSettings,
)

__all__ = ["GRUPredictor", "LSTMPredictor", "MultiPointGRU", "MultiPointLSTM",
           "MultiPointTCN", "NeuralPredictor", "TCNPredictor"]


def _sigmoid(x: np.ndarray) -> np.ndarray:
    return 0.5 * (1.0 + np.tanh(0.5 * x))  # no overflow warning for large |x|


class _Cells:
    """One recurrent network's weights as NumPy arrays, and its step."""

    def __init__(self, kind: str, net) -> None:
        sd = {k: v.detach().double().numpy() for k, v in net.state_dict().items()}
        self.kind, self.layers = kind, net.rnn.num_layers
        self.w_ih = [sd[f"rnn.weight_ih_l{i}"] for i in range(self.layers)]
        self.w_hh = [sd[f"rnn.weight_hh_l{i}"] for i in range(self.layers)]
        self.b_ih = [sd[f"rnn.bias_ih_l{i}"] for i in range(self.layers)]
        self.b_hh = [sd[f"rnn.bias_hh_l{i}"] for i in range(self.layers)]
        self.head_w, self.head_b = sd["head.weight"], sd["head.bias"]
        self.hidden = self.w_hh[0].shape[1]

    def zero(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((self.layers, self.hidden)), np.zeros((self.layers, self.hidden))

    def step(self, x: np.ndarray, h: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Advance the state (h, c) in place with input x; return the head's output.

        LSTM: [i; f; g; o] = W_ih x + b_ih + W_hh h + b_hh, c ← σ(f)c + σ(i)tanh(g),
        h ← σ(o)tanh(c). GRU: r, u = σ(·) of their rows, m = tanh(W_in x + b_in + r(W_hn h +
        b_hn)), h ← (1 − u)m + u h.
        """
        H = self.hidden
        for i in range(self.layers):
            gi = self.w_ih[i] @ x + self.b_ih[i]
            gh = self.w_hh[i] @ h[i] + self.b_hh[i]
            if self.kind == "lstm":
                g = gi + gh
                c[i] = _sigmoid(g[H : 2 * H]) * c[i] + _sigmoid(g[:H]) * np.tanh(g[2 * H : 3 * H])
                h[i] = _sigmoid(g[3 * H :]) * np.tanh(c[i])
            else:
                r = _sigmoid(gi[:H] + gh[:H])
                u = _sigmoid(gi[H : 2 * H] + gh[H : 2 * H])
                m = np.tanh(gi[2 * H :] + r * gh[2 * H :])
                h[i] = (1.0 - u) * m + u * h[i]
            x = h[i]
        return self.head_w @ x + self.head_b


class _Causal:
    """One TCN's weights as NumPy arrays, run one sample at a time (Paine et al. 2016, "Fast
    WaveNet generation", arXiv:1611.09482): each convolution keeps the inputs it still needs,
    zeros before the first sample, as the training's left padding."""

    def __init__(self, net) -> None:
        sd = {k: v.detach().double().numpy() for k, v in net.state_dict().items()}
        self.blocks = []
        for i, block in enumerate(net.blocks):
            pre = f"blocks.{i}."
            skip = (sd[pre + "skip.weight"][:, :, 0], sd[pre + "skip.bias"]) \
                if pre + "skip.weight" in sd else None
            self.blocks.append((sd[pre + "conv1.weight"], sd[pre + "conv1.bias"],
                                sd[pre + "conv2.weight"], sd[pre + "conv2.bias"], skip,
                                block.conv1.dilation[0]))
        self.head_w, self.head_b = sd["head.weight"][:, :, 0], sd["head.bias"]

    def zero(self) -> tuple[list[np.ndarray], list[int]]:
        """Per convolution, a ring of its last (k − 1)·dilation + 1 inputs; the write index."""
        rings = []
        for w1, _, w2, _, _, dil in self.blocks:
            span = (w1.shape[2] - 1) * dil + 1
            rings += [np.zeros((span, w1.shape[1])), np.zeros((span, w2.shape[1]))]
        return rings, [0]

    def step(self, x: np.ndarray, rings: list[np.ndarray], clock: list[int]) -> np.ndarray:
        """Feed input x; return the head's output. A convolution of kernel k and dilation δ:
        y_t = b + Σ_j W_j x_{t − (k − 1 − j)δ}; a block: relu(relu-conv(relu-conv(x)) + skip)."""
        t = clock[0]
        clock[0] = t + 1
        for i, (w1, b1, w2, b2, skip, dil) in enumerate(self.blocks):
            h = np.maximum(_conv(rings[2 * i], x, w1, b1, dil, t), 0.0)
            y = np.maximum(_conv(rings[2 * i + 1], h, w2, b2, dil, t), 0.0)
            x = np.maximum(y + (x if skip is None else skip[0] @ x + skip[1]), 0.0)
        return self.head_w @ x + self.head_b


def _conv(ring: np.ndarray, x: np.ndarray, w: np.ndarray, b: np.ndarray, dil: int,
          t: int) -> np.ndarray:
    """Write x at time t into ``ring`` and return the causal convolution's output at t."""
    span, k = ring.shape[0], w.shape[2]
    ring[t % span] = x
    out = b.copy()
    for j in range(k):
        out += w[:, :, j] @ ring[(t - (k - 1 - j) * dil) % span]
    return out


class NeuralPredictor(FittedPredictor):
    """A neural forecaster of the POI from its own past (module docstring)."""

    Settings = NetworkSettings
    SUFFIX = ".pt"
    PRESETS = LSTM_PRESETS

    # -- fitting ------------------------------------------------------------------
    def _heads(self) -> list[list[int]]:
        """The leads each network forecasts."""
        L = self.settings.leads
        return [list(range(L))] if self.settings.heads == "joint" else [[k] for k in range(L)]

    def _data(self, series, cut: float | None = None):
        """Inputs (B, T, C), targets (B, T, L·d) and their mask, z-scored; with ``cut``, only
        the targets inside each series' first ``cut`` fraction count."""
        mean, std = self._stats
        d, L = series[0].shape[2], self.settings.leads
        T = max(a.shape[0] for a in series)
        x = np.zeros((len(series), T, mean.size))
        y = np.full((len(series), T, L * d), np.nan)
        for b, a in enumerate(series):
            z = (a.reshape(a.shape[0], -1) - mean) / std
            x[b, : a.shape[0]] = fill_forward(z)
            end = a.shape[0] if cut is None else round(cut * a.shape[0])
            for k in range(1, L + 1):
                if end > k:
                    y[b, : end - k, (k - 1) * d : k * d] = z[k:end, :d]
        mask = np.isfinite(y)
        return x, np.where(mask, y, 0.0), mask

    def _train_all(self, x, y, mask, progress) -> list:
        """The networks, ensemble-major: [member][head]."""
        s, d, heads = self.settings, self._dim, self._heads()
        seeds = np.random.SeedSequence(s.seed).spawn(s.ensemble * len(heads))
        nets = []
        for e in range(s.ensemble):
            row = []
            for j, leads in enumerate(heads):
                cols = np.concatenate([np.arange(k * d, (k + 1) * d) for k in leads])
                seed = int(seeds[e * len(heads) + j].generate_state(1)[0])
                if progress is not None:
                    progress(f"network {e * len(heads) + j + 1}/{len(seeds)}")
                row.append(train(s, x, y[:, :, cols], mask[:, :, cols], seed))
            nets.append(row)
        return nets

    def _fit(self, series: list[np.ndarray], progress) -> dict:
        s = self.settings
        self._dim = series[0].shape[2]
        self._stats = channel_stats(series)
        model = {"mean": self._stats[0], "std": self._stats[1], "validation_rms": None}
        if s.validation > 0.0:
            x, y, mask = self._data(series, 1.0 - s.validation)
            nets = self._train_all(x, y, mask, progress)
            model["validation_rms"] = self._validate(nets, series, 1.0 - s.validation)
        x, y, mask = self._data(series)
        model["nets"] = self._train_all(x, y, mask, progress)
        return model

    def _validate(self, nets, series, cut: float) -> np.ndarray:
        """RMS error [m] per lead of the forecasts issued in each series' last part."""
        mean, std = self._stats
        d, L = self._dim, self.settings.leads
        sq, count = np.zeros(L), np.zeros(L)
        for a in series:
            z = fill_forward((a.reshape(a.shape[0], -1) - mean) / std)
            out = self._outputs(nets, z)  # (T, L·d) z-scored forecasts issued at every t
            start = round(cut * a.shape[0])
            for k in range(1, L + 1):
                f = out[start : a.shape[0] - k, (k - 1) * d : k * d] * std[:d] + mean[:d]
                e = np.sum((f - a[start + k :, 0]) ** 2, axis=1)
                sq[k - 1] += np.nansum(e)
                count[k - 1] += np.isfinite(e).sum()
        return np.sqrt(sq / np.maximum(count, 1))

    def _outputs(self, nets, z: np.ndarray) -> np.ndarray:
        """The ensemble's mean outputs (T, L·d) over a whole z-scored sequence (T, C)."""
        heads = self._heads()
        with torch.inference_mode():
            xt = torch.as_tensor(z[None], dtype=torch.float32)
            outs = [torch.cat([net(xt)[0] for net in row], dim=1).double().numpy()
                    for row in nets]
        order = np.concatenate([np.arange(k * self._dim, (k + 1) * self._dim)
                                for leads in heads for k in leads])
        out = np.empty_like(outs[0])
        out[:, order] = np.mean(outs, axis=0)
        return out

    # -- online -------------------------------------------------------------------
    def _warmup(self) -> int:
        """A TCN: its span; a recurrent network: 1 s of samples (a beat at 60 beats/min)."""
        if self.settings.architecture == "tcn":
            return self.settings.span
        return max(1, round(1.0 / self.dt))

    def _allocate(self, d: int) -> None:
        super()._allocate(d)
        m = self.model
        self._stats = (m["mean"], m["std"])
        self._dim = m["dim"]
        if self.settings.architecture == "tcn":
            self._runs = [[_Causal(net) for net in row] for row in m["nets"]]
        else:
            self._runs = [[_Cells(self.settings.architecture, net) for net in row]
                          for row in m["nets"]]
        self._state = [[run.zero() for run in row] for row in self._runs]
        self._out: np.ndarray | None = None

    def _advance(self, row: np.ndarray) -> None:
        mean, std = self._stats
        x = (row - mean) / std
        outs = [np.concatenate([run.step(x, *state) for run, state in
                                zip(runs, states, strict=True)])
                for runs, states in zip(self._runs, self._state, strict=True)]
        self._out = np.mean(outs, axis=0)

    def _forecast(self) -> np.ndarray:
        mean, std = self._stats
        d = self._dim
        order = [k for leads in self._heads() for k in leads]
        f = np.empty((self.settings.leads, d))
        f[order] = self._out.reshape(-1, d)
        return mean[:d] + std[:d] * f

    # -- files ----------------------------------------------------------------------
    def save(self, path) -> None:
        """Write the model to ``path`` (``torch.save`` of tensors, the networks' state dicts and
        the settings as JSON; :meth:`load` reads it with ``weights_only=True``)."""
        if self.model is None:
            raise RuntimeError(f"{type(self).__name__} is not fitted: nothing to save")
        m = self.model
        val = m["validation_rms"]
        torch.save({
            "kind": type(self).__name__, "settings": settings_to_json(self.settings),
            "mean": torch.as_tensor(m["mean"]), "std": torch.as_tensor(m["std"]),
            "validation_rms": None if val is None else torch.as_tensor(val),
            "nets": [[net.state_dict() for net in row] for row in m["nets"]],
            "points": m["points"], "dim": m["dim"], "dt": m["dt"],
        }, path)

    def _read(self, path):
        f = torch.load(path, map_location="cpu", weights_only=True)
        if f.get("kind") != type(self).__name__:
            raise ValueError(f"{path}: a {f.get('kind')} model, not a {type(self).__name__}")
        s = settings_from_json(self.Settings, f["settings"])
        d, P = int(f["dim"]), int(f["points"])
        q = d * (s.leads if s.heads == "joint" else 1)
        nets = []
        for row in f["nets"]:
            nets.append([])
            for state in row:
                net = build(s, P * d, q)
                net.load_state_dict(state)
                nets[-1].append(net.eval())
        val = f["validation_rms"]
        model = {"mean": f["mean"].numpy(), "std": f["std"].numpy(), "nets": nets,
                 "validation_rms": None if val is None else val.numpy(),
                 "points": P, "dim": d, "dt": float(f["dt"])}
        return s, model


class LSTMPredictor(NeuralPredictor):
    """LSTM forecaster of the POI from its own past (presets ``zhang2022``, ``xu2026``)."""

    PRESETS = LSTM_PRESETS


class GRUPredictor(NeuralPredictor):
    """GRU forecaster of the POI from its own past (preset ``li2022``)."""

    PRESETS = GRU_PRESETS


class TCNPredictor(NeuralPredictor):
    """TCN forecaster of the POI from its own past (preset ``xu2026``)."""

    PRESETS = TCN_PRESETS


class MultiPointLSTM(LSTMPredictor):
    """LSTM forecaster of the POI from every tracked point's past (ST-LSTM)."""

    multi_point = True


class MultiPointGRU(GRUPredictor):
    """GRU forecaster of the POI from every tracked point's past (ST-GRU)."""

    multi_point = True


class MultiPointTCN(TCNPredictor):
    """TCN forecaster of the POI from every tracked point's past."""

    multi_point = True
