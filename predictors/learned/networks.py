"""The networks and their training (PyTorch; imported only by
:mod:`rhmpc.predictors.learned.neural`).

Recurrent networks (``nn.LSTM``/``nn.GRU`` and a linear head) and the temporal convolutional
network of Bai, Kolter & Koltun 2018 (arXiv:1803.01271, Fig. 1): residual blocks of two causal
dilated convolutions, each followed by a ReLU (and dropout in training), a 1×1 convolution on
the skip path where the channel count changes, a ReLU after the sum, and a 1×1 head. Both map
a sequence (B, T, C) to outputs (B, T, q) causally: output t reads inputs ≤ t.

Training (:func:`train`): full batch over the training series (zero-padded to one length and
masked), mean squared error, Adam (Kingma & Ba 2015) with a step decay of the learning rate
and gradient-norm clipping, every random draw from ``torch.manual_seed(seed)``, with
deterministic algorithms on one CPU thread.
"""

from __future__ import annotations

import contextlib
import os

import numpy as np
import torch
from torch import nn

__all__ = ["TCN", "Recurrent", "build", "train"]


class Recurrent(nn.Module):
    """An LSTM or GRU of ``layers`` × ``hidden`` units and a linear head to ``q`` outputs."""

    def __init__(self, kind: str, inputs: int, hidden: int, layers: int, q: int,
                 dropout: float) -> None:
        super().__init__()
        cls = nn.LSTM if kind == "lstm" else nn.GRU
        self.rnn = cls(inputs, hidden, layers, batch_first=True,
                       dropout=dropout if layers > 1 else 0.0)
        self.head = nn.Linear(hidden, q)

    def run(self, x: torch.Tensor, state=None) -> tuple[torch.Tensor, object]:
        """Outputs (B, T, q) over inputs ``x`` (B, T, C) from ``state`` (zeros if None), and
        the state after the last input: the one definition of the network, run over whole
        sequences in training and one sample at a time online."""
        y, state = self.rnn(x, state)
        return self.head(y), state

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.run(x)[0]


class _Block(nn.Module):
    """Residual block: x + relu(conv(relu(conv(x)))) with causal dilated convolutions."""

    def __init__(self, cin: int, cout: int, kernel: int, dilation: int, dropout: float) -> None:
        super().__init__()
        self.pad = (kernel - 1) * dilation
        self.conv1 = nn.Conv1d(cin, cout, kernel, dilation=dilation)
        self.conv2 = nn.Conv1d(cout, cout, kernel, dilation=dilation)
        self.drop = nn.Dropout(dropout)
        self.skip = nn.Conv1d(cin, cout, 1) if cin != cout else nn.Identity()

    def forward(self, x: torch.Tensor, past=None) -> tuple[torch.Tensor, tuple]:
        """Outputs (B, C', T) over inputs ``x`` (B, C, T), each convolution's left context
        taken from ``past`` (the last ``pad`` columns of its inputs before ``x``; zeros when
        None, the training's padding); and the ``past`` of the next call."""
        if past is None:
            past = (x.new_zeros(x.shape[0], x.shape[1], self.pad),
                    x.new_zeros(x.shape[0], self.conv1.out_channels, self.pad))
        a = torch.cat([past[0], x], dim=2)
        h = self.drop(torch.relu(self.conv1(a)))
        b = torch.cat([past[1], h], dim=2)
        y = self.drop(torch.relu(self.conv2(b)))
        keep = slice(x.shape[2], None)  # the last pad columns of a and b
        return torch.relu(y + self.skip(x)), (a[:, :, keep], b[:, :, keep])


class TCN(nn.Module):
    """Temporal convolutional network: a block per dilation and a 1×1 head to ``q`` outputs."""

    def __init__(self, inputs: int, channels: int, dilations, kernel: int, q: int,
                 dropout: float) -> None:
        super().__init__()
        sizes = [inputs] + [channels] * len(dilations)
        self.blocks = nn.ModuleList(_Block(sizes[i], sizes[i + 1], kernel, dil, dropout)
                                    for i, dil in enumerate(dilations))
        self.head = nn.Conv1d(channels, q, 1)

    def run(self, x: torch.Tensor, state=None) -> tuple[torch.Tensor, list]:
        """Outputs (B, T, q) over inputs ``x`` (B, T, C) after the inputs ``state`` holds
        (each convolution's left context; None: the start of a sequence), and the state after
        the last input (Paine et al. 2016, "Fast WaveNet generation", arXiv:1611.09482: one
        new input costs one column per convolution)."""
        h, after = x.transpose(1, 2), []
        for block, past in zip(self.blocks, state or [None] * len(self.blocks), strict=True):
            h, past = block(h, past)
            after.append(past)
        return self.head(h).transpose(1, 2), after

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (B, T, C) -> (B, T, q)
        return self.run(x)[0]


def build(s, inputs: int, q: int) -> nn.Module:
    """The network of settings ``s``
    (:class:`rhmpc.predictors.learned.settings.NetworkSettings`)."""
    if s.architecture == "tcn":
        return TCN(inputs, s.channels, s.dilations, s.kernel, q, s.dropout)
    return Recurrent(s.architecture, inputs, s.hidden, s.layers, q, s.dropout)


def device_of(s) -> torch.device:
    """The training device of setting ``s.device`` (``auto``: CUDA if present)."""
    if s.device == "cuda" or (s.device == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise ValueError("device 'cuda' asked for, but PyTorch sees no CUDA GPU")
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # deterministic cuBLAS
        return torch.device("cuda")
    return torch.device("cpu")


@contextlib.contextmanager
def deterministic():
    """Deterministic algorithms on one CPU thread inside the block (the previous mode and
    thread count restored after): the same seed gives the same network bit for bit on any
    machine's CPU, and a small sequential network trains fastest on one thread."""
    before, threads = torch.are_deterministic_algorithms_enabled(), torch.get_num_threads()
    torch.use_deterministic_algorithms(True)
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before)
        torch.set_num_threads(threads)


def train(s, x: np.ndarray, y: np.ndarray, mask: np.ndarray, seed: int) -> nn.Module:
    """A network of settings ``s`` fitted to inputs ``x`` (B, T, C), targets ``y`` (B, T, q)
    and the mask (B, T, q) of the targets that count, from ``torch.manual_seed(seed)``.
    Returns it on the CPU, in evaluation mode."""
    device = device_of(s)
    with deterministic():
        torch.manual_seed(seed)
        net = build(s, x.shape[2], y.shape[2]).to(device)
        xt, yt, mt = (torch.as_tensor(a, dtype=torch.float32, device=device) for a in (x, y, mask))
        count = mt.sum().clamp(min=1.0)
        opt = torch.optim.Adam(net.parameters(), lr=s.learning_rate, weight_decay=s.weight_decay)
        sched = torch.optim.lr_scheduler.StepLR(opt, s.lr_drop_period, s.lr_drop_factor)
        net.train()
        for _ in range(s.epochs):
            inp = xt + s.input_noise * torch.randn_like(xt) if s.input_noise > 0 else xt
            loss = (((net(inp) - yt) * mt) ** 2).sum() / count
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(net.parameters(), s.gradient_clip)
            opt.step()
            sched.step()
    return net.cpu().eval()
