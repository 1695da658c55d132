"""Settings and the literature's presets of the neural predictors (no PyTorch needed here).

The presets are the architectures and training settings of the papers that predict the
heart's point of interest (POI) from stereo-video tracks at 25 frames/s:

``zhang2022``
    Zhang, Yao, Yang, Zheng, Liu, "Motion prediction of beating heart using spatio-temporal
    LSTM", IEEE Signal Process. Lett. 29:787, 2022 (code ``zwr-04/ST-LSTM``): one LSTM layer of
    300 units and a linear head, Adam with learning rate 0.01 dropped ×0.2 every 100 epochs,
    gradients clipped to norm 1, 200 epochs, trained on the whole training sequence at once
    (its state carried from the first sample), one direct model per lead.
``xu2026``
    Xu et al., CMES 146(1), 2026: an LSTM of 2 × 600 units (``lstm``), and a temporal
    convolutional network (``tcn``, Bai, Kolter, Koltun 2018, arXiv:1803.01271) of 4 residual
    blocks of 64 channels with dilations 1, 2, 4, 8. The kernel size, 3, is chosen here (the
    smallest odd kernel; a span of 61 samples, 2.4 s at 25 frames/s, two to three beats), and
    so are the training settings, those of ``zhang2022``.
``li2022``
    Li, Yang, Zhang, Zheng, Liu, "Motion prediction for beating heart surgery with GRU"
    (SSRN 2022; code ``oww-file/ST-GRU``): 2 GRU layers of 300 units with dropout 0.1 between
    them, Adam with learning rate 0.01 and weight decay 1e-6, 100 epochs; the learning-rate
    drop and the gradient clip of ``zhang2022``, and its training on whole sequences (the
    code trains on single samples, without a recurrent memory).

Every preset is one network per lead and seed (``ensemble`` = 1); ``ensemble``,
``input_noise`` and ``heads`` change that without changing the architecture.
"""

from __future__ import annotations

from dataclasses import dataclass

from rhmpc.predictors.base import PredictorSettings

__all__ = [
    "ARCHITECTURES",
    "GRU_PRESETS",
    "HEADS",
    "LSTM_PRESETS",
    "TCN_PRESETS",
    "NetworkSettings",
]

ARCHITECTURES = ("lstm", "gru", "tcn")
HEADS = ("per-lead", "joint")
DEVICES = ("auto", "cpu", "cuda")


@dataclass(frozen=True)
class NetworkSettings(PredictorSettings):
    """Settings of a neural predictor (defaults: ``zhang2022``).

    The network maps the z-scored history of the points (z-scored with the mean and standard
    deviation of each channel over the training data only) to the z-scored POI at lead k,
    ẑ_{n+k} = μ + σ ⊙ f_k(history ≤ n), trained by minimising the mean squared error over
    every instant of the training series.

    Attributes
    ----------
    architecture : str
        ``"lstm"``, ``"gru"`` (recurrent: the state runs from the first sample, one step per
        sample) or ``"tcn"`` (causal dilated convolutions over the last ``span`` samples).
    hidden : int
        Units per recurrent layer [-]; 300 (Zhang et al. 2022).
    layers : int
        Recurrent layers [-]; 1 (Zhang et al. 2022).
    channels : int
        Channels of every TCN block [-]; 64 (Xu et al. 2026).
    dilations : tuple of int
        One TCN residual block (two causal convolutions) per dilation [-]; (1, 2, 4, 8) (Xu
        et al. 2026). Span R = 1 + 2(kernel − 1)·Σ dilations samples.
    kernel : int
        TCN kernel size [-]; 3.
    dropout : float
        Dropout between recurrent layers, or after every TCN convolution, in training [-].
    heads : str
        ``"per-lead"``: one network per lead (direct models, Zhang et al. 2022); ``"joint"``:
        one network whose head emits every lead (multi-output).
    leads : int
        L, leads forecast [samples]; 4 (160 ms at 25 frames/s); a longer forecast holds the
        lead-L one.
    epochs : int
        Full-batch passes over the training series [-]; 200 (Zhang et al. 2022).
    learning_rate : float
        Adam's initial step size [-]; 0.01 (Zhang et al. 2022).
    lr_drop_period, lr_drop_factor : int, float
        The step size is multiplied by ``lr_drop_factor`` every ``lr_drop_period`` epochs;
        100 and 0.2 (Zhang et al. 2022).
    gradient_clip : float
        Largest gradient norm [-]; 1 (Zhang et al. 2022).
    weight_decay : float
        Adam's L2 weight decay [-]; 0 (Zhang et al. 2022).
    input_noise : float
        σ of the Gaussian noise added to the z-scored inputs at every epoch [-] (training with
        noise, a Tikhonov regulariser: Bishop 1995, Neural Comput. 7:108); 0.
    ensemble : int
        Networks per lead trained from different seeds and averaged [-]; 1.
    seed : int
        Seed of every random draw of the training (initial weights, dropout, noise).
    validation : float
        Fraction of each training series held out for a first fit whose RMS forecast error
        there is the model's out-of-sample estimate (``validation_rms``) [-]; the model is then
        fitted again on everything. 0.2, the ridge's: an online combination weighs a member by
        that estimate until it has scored the member's own forecasts (the training samples
        tell nothing of a network's error); 0: no estimate, one fit (1.8 times faster).
    device : str
        ``"auto"`` (a CUDA GPU if present, else the CPU), ``"cpu"`` or ``"cuda"``: where the
        training runs; forecasts run on the CPU.
    unit : float or None
        Metres per data unit of the online samples (1.0 for m, 1e-3 for mm); ``None``:
        inferred.
    model : str or None
        A file written by ``save`` to load at construction.
    """

    architecture: str = "lstm"
    hidden: int = 300
    layers: int = 1
    channels: int = 64
    dilations: tuple[int, ...] = (1, 2, 4, 8)
    kernel: int = 3
    dropout: float = 0.0
    heads: str = "per-lead"
    leads: int = 4
    epochs: int = 200
    learning_rate: float = 0.01
    lr_drop_period: int = 100
    lr_drop_factor: float = 0.2
    gradient_clip: float = 1.0
    weight_decay: float = 0.0
    input_noise: float = 0.0
    ensemble: int = 1
    seed: int = 0
    validation: float = 0.2
    device: str = "auto"
    unit: float | None = None
    model: str | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, options in (("architecture", ARCHITECTURES), ("heads", HEADS),
                              ("device", DEVICES)):
            if getattr(self, name) not in options:
                raise ValueError(f"{name} must be one of {options}, got {getattr(self, name)!r}")
        for name in ("hidden", "layers", "channels", "kernel", "leads", "epochs",
                     "lr_drop_period", "ensemble"):
            v = getattr(self, name)
            if isinstance(v, bool) or int(v) != v or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if not self.dilations or any(int(v) != v or v < 1 for v in self.dilations):
            raise ValueError(f"dilations must be integers >= 1, got {self.dilations!r}")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")
        for name, lo, hi in (("dropout", 0.0, 1.0), ("validation", 0.0, 1.0)):
            v = getattr(self, name)
            if not lo <= v < hi:
                raise ValueError(f"{name} must be in [{lo:g}, {hi:g}), got {v!r}")
        for name in ("learning_rate", "lr_drop_factor", "gradient_clip"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("weight_decay", "input_noise"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")

    @property
    def span(self) -> int:
        """R, the samples a TCN forecast reads (its receptive field)."""
        return 1 + 2 * (self.kernel - 1) * sum(self.dilations)


_ZHANG = NetworkSettings()
#: the LSTM presets: ``zhang2022`` (the default) and ``xu2026``
LSTM_PRESETS = {
    "zhang2022": _ZHANG,
    "xu2026": NetworkSettings(hidden=600, layers=2),
}
#: the GRU preset ``li2022``
GRU_PRESETS = {
    "li2022": NetworkSettings(architecture="gru", hidden=300, layers=2, dropout=0.1,
                              epochs=100, weight_decay=1e-6),
}
#: the TCN preset ``xu2026``
TCN_PRESETS = {
    "xu2026": NetworkSettings(architecture="tcn"),
}
