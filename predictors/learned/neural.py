"""Neural predictors: LSTM, GRU and TCN forecasters of the POI, fitted before the run
(PyTorch), then online on the `Predictor` contract.

Names: ``lstm``, ``gru``, ``tcn`` read the POI only; ``st-lstm``, ``st-gru``, ``st-tcn`` read
every tracked point (the spatio-temporal models of Zhang et al. 2022 and Li et al. 2022,
which feed the other points' past as well as the POI's). The architectures and training
settings are the papers' (:mod:`rhmpc.predictors.learned.settings`).

Fitting.  Every channel is z-scored with its mean and standard deviation over the training
series; a missing input takes the channel's previous value. For each lead k (or all at once,
``heads="joint"``) and each of the ``ensemble`` seeds, a network is trained on the sequences
(:func:`rhmpc.predictors.learned.networks.train`), the target at instant t the z-scored POI at
t + k. Seeds: ``numpy.random.SeedSequence(seed)`` spawns one per network.

Online.  The networks run one step per sample through their own modules, from the state at
the start of a sequence as in training (:meth:`~rhmpc.predictors.learned.networks.Recurrent.run`: a
recurrent network's state; :meth:`~rhmpc.predictors.learned.networks.TCN.run`: a TCN's last inputs
of each convolution, zeros before the first sample as the training's padding), one definition
for both. The forecast is the mean of the ensemble, ẑ_{n+k} = μ + σ ⊙ mean_e f_{k,e}.
"""

from __future__ import annotations

import contextlib

import numpy as np
import torch

from rhmpc.io import FileError
from rhmpc.predictors.learned.fitted import FittedPredictor
from rhmpc.predictors.learned.networks import build, train
from rhmpc.predictors.learned.series import channel_stats, fill_forward
from rhmpc.predictors.learned.settings import (
    GRU_PRESETS,
    LSTM_PRESETS,
    TCN_PRESETS,
    NetworkSettings,
)

__all__ = ["GRUPredictor", "LSTMPredictor", "MultiPointGRU", "MultiPointLSTM",
           "MultiPointTCN", "NeuralPredictor", "TCNPredictor"]


@contextlib.contextmanager
def _batch_of_one():
    """PyTorch's own CPU kernels inside, not oneDNN's (``torch.backends.mkldnn.enabled``): for
    one sample of one sequence, oneDNN's recurrent kernel is made for batches, and PyTorch's
    own is the faster one; and one thread: a step's operations are too small to share, and
    threads that wait on each other for them cost ten times the step on a busy machine
    (a TCN's step, 5 networks: 20 ms on one thread, 200 ms on two, both cores loaded)."""
    before, threads = torch.backends.mkldnn.enabled, torch.get_num_threads()
    torch.backends.mkldnn.enabled = False
    if threads != 1:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.backends.mkldnn.enabled = before
        if threads != 1:
            torch.set_num_threads(threads)


class NeuralPredictor(FittedPredictor):
    """A neural forecaster of the POI from its own past (module docstring)."""

    Settings = NetworkSettings
    KIND = "lstm"
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
        self._state = [[None] * len(row) for row in m["nets"]]  # from the start of a sequence
        self._out: np.ndarray | None = None

    def _advance(self, row: np.ndarray) -> None:
        mean, std = self._stats
        x = torch.as_tensor((row - mean) / std, dtype=torch.float32)[None, None]
        outs = []
        with torch.inference_mode(), _batch_of_one():
            for nets, states in zip(self.model["nets"], self._state, strict=True):
                ys = []
                for j, net in enumerate(nets):
                    y, states[j] = net.run(x, states[j])
                    ys.append(y[0, -1])
                outs.append(torch.cat(ys).double().numpy())
        self._out = np.mean(outs, axis=0)

    def _forecast(self) -> np.ndarray:
        mean, std = self._stats
        d = self._dim
        order = [k for leads in self._heads() for k in leads]
        f = np.empty((self.settings.leads, d))
        f[order] = self._out.reshape(-1, d)
        return mean[:d] + std[:d] * f

    # -- the model's file ------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        m = self.model
        out = {"mean": m["mean"], "std": m["std"]}
        if m["validation_rms"] is not None:
            out["validation_rms"] = m["validation_rms"]
        for e, row in enumerate(m["nets"]):
            for j, net in enumerate(row):
                out.update({f"net.{e}.{j}.{k}": v.detach().cpu().numpy()
                            for k, v in net.state_dict().items()})
        return out

    @staticmethod
    def _head_width(settings, dim: int) -> int:
        """Outputs of each network: every lead's coordinates (joint), or one lead's."""
        return dim * (settings.leads if settings.heads == "joint" else 1)

    def model_shapes(self, settings, saved):
        """The networks' tensors as the settings build them (on PyTorch's ``meta`` device:
        shapes only, nothing allocated), per ensemble member e and head j ``net.e.j.NAME``;
        the channels' ``mean`` and ``std``; ``validation_rms`` (L,) when it was estimated."""
        C = (saved.points if self.multi_point else 1) * saved.dim
        nets = settings.ensemble * (1 if settings.heads == "joint" else settings.leads)
        shapes = {"mean": (C,), "std": (C,)}
        if nets > len(saved.shapes):  # each network holds a tensor at least
            raise FileError(f"{saved.path}: the model's settings make {nets} networks; the "
                            f"file holds {len(saved.shapes)} arrays: a damaged or altered file")
        try:
            with torch.device("meta"):
                net = build(settings, C, self._head_width(settings, saved.dim))
        except (RuntimeError, ValueError, OverflowError) as exc:  # sizes past any tensor's
            raise FileError(f"{saved.path}: the model's settings make a network no file "
                            f"holds ({str(exc).splitlines()[0]}): a damaged or altered file"
                            ) from None
        tensors = {k: tuple(v.shape) for k, v in net.state_dict().items()}
        for e in range(settings.ensemble):
            for j in range(nets // settings.ensemble):
                shapes.update({f"net.{e}.{j}.{k}": v for k, v in tensors.items()})
        if "validation_rms" in saved.shapes:
            shapes["validation_rms"] = (settings.leads,)
        return shapes, ()

    def _restore(self, settings, arrays, saved) -> dict:
        C = (saved.points if self.multi_point else 1) * saved.dim
        q = self._head_width(settings, saved.dim)
        heads = 1 if settings.heads == "joint" else settings.leads
        nets = []
        for e in range(settings.ensemble):
            nets.append([])
            for j in range(heads):
                net = build(settings, C, q)
                prefix = f"net.{e}.{j}."
                net.load_state_dict({k[len(prefix):]: torch.from_numpy(v)
                                     for k, v in arrays.items() if k.startswith(prefix)})
                nets[-1].append(net.eval())
        return {"mean": arrays["mean"], "std": arrays["std"], "nets": nets,
                "validation_rms": arrays.get("validation_rms")}


class LSTMPredictor(NeuralPredictor):
    """LSTM forecaster of the POI from its own past (presets ``zhang2022``, ``xu2026``)."""

    KIND = "lstm"
    PRESETS = LSTM_PRESETS


class GRUPredictor(NeuralPredictor):
    """GRU forecaster of the POI from its own past (preset ``li2022``)."""

    KIND = "gru"
    PRESETS = GRU_PRESETS


class TCNPredictor(NeuralPredictor):
    """TCN forecaster of the POI from its own past (preset ``xu2026``)."""

    KIND = "tcn"
    PRESETS = TCN_PRESETS


class MultiPointLSTM(LSTMPredictor):
    """LSTM forecaster of the POI from every tracked point's past (ST-LSTM)."""

    KIND = "st-lstm"
    multi_point = True


class MultiPointGRU(GRUPredictor):
    """GRU forecaster of the POI from every tracked point's past (ST-GRU)."""

    KIND = "st-gru"
    multi_point = True


class MultiPointTCN(TCNPredictor):
    """TCN forecaster of the POI from every tracked point's past."""

    KIND = "st-tcn"
    multi_point = True
