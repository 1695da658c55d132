r"""The sonomicrometer from its physics (Sonometrics; Tuna et al. 2013 §III-A).

A POI crystal sutured on the heart and ``count`` reference crystals on a rigid base
(:class:`~rhmpc.sim.sensors.crystals.CrystalArray`). Every sample, the instrument measures the time
of flight of an ultrasound pulse from each reference crystal to the POI crystal, converts it to
a range with the speed of sound it is set to, and solves the 3-D position by trilateration
(:func:`~rhmpc.sim.sensors.trilateration.trilaterate`). Per range i and sample k:

.. math::

    \begin{aligned}
    d_i &= \lVert x_k - b_i \rVert,\quad x_k = x_0 + p(t_k) - p(t_0)
        && \text{true distance} \\
    \delta_i &= \tfrac{\lambda}{4}\,(g_i^0 - g_i),\quad g_i = \cos\theta_i \cos\phi_i
        && \text{leading-edge error, } |\delta_i| \le \lambda/4 \\
    w_i &\sim \mathcal{N}(0, \sigma_r^2) \text{ white}
        && \text{crystal-geometry error (Tuna §IX)} \\
    s_i &\in \{0, \lambda\}
        && \text{cycle slip (echo outlier), rare} \\
    \tau_i &= \Delta \operatorname{round}\Bigl(\frac{d_i + \delta_i + w_i + s_i}
                                                {c\,(1 + \varepsilon)\,\Delta}\Bigr)
        && \text{time of flight, counter step } \Delta \\
    r_i &= c\,\tau_i
        && \text{range with the set speed of sound } c \\
    z_k &= \operatorname{trilaterate}(b, r) - x_0 + p(t_0)
        && \text{back in the motion's frame}
    \end{aligned}

θ_i is the angle between the POI crystal's axis and the line to crystal i, φ_i that between the
reference crystal's axis (the base's normal) and the line to the POI: the received amplitude
falls with the obliquity g_i, and the threshold on the pulse's leading edge then fires up to a
quarter cycle later (Tuna §III-A, §IX: the crystals' geometry and the leading edge are the main
error, "approximately one-fourth wavelength"). The constant part, g_i⁰ at the rest pose, is the
per-crystal delay the instrument's software calibrates away (SonoSOFT's offset). The POI
crystal's axis turns with the heart wall: n = normalise(n₀ + d⊥/L), d⊥ the displacement
across n₀ and L the lever (a rotation of the wall by d⊥/L rad). The error is smooth and follows
the motion: it is not white. The rest of the crystal-geometry error — where on the crystal's face
the wave front is received, which changes with the crystals' shape and their orientation from
sample to sample — is what §IX says "might be approximated by a white noise" (citing Ratcliffe et
al., IEEE TBME 42(6), 1995): w_i, independent per range and sample. ε is the relative error of
the speed of sound, one draw per run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from rhmpc.sim.sensors.crystals import CrystalArray
from rhmpc.sim.sensors.events import Dropouts
from rhmpc.sim.sensors.playback import Upsample
from rhmpc.sim.sensors.stream import SampleStream, Sensor, delivery_stages
from rhmpc.sim.sensors.trilateration import trilaterate


@dataclass(frozen=True)
class SonomicrometrySettings:
    """The physical sonomicrometer: every default with its source.

    Attributes
    ----------
    rate : float
        Sample rate [Hz]: 257 or 404 in Tuna et al. §III-A (the device reaches 2 kHz).
    crystals : CrystalArray
        Reference base and POI crystal geometry (five crystals on a 50-mm circle, §III-A).
    sound_speed : float
        Speed of sound the instrument converts times of flight with, c [m/s]: 1590 m/s, the
        value with which Sonometrics quotes its step (``7.8`` ns ≈ 12 µm).
    sound_speed_error : float
        Standard deviation of the relative error ε of the true speed against ``sound_speed``
        [-], one draw per run: 0.2 %. The balloon's glycerine solution is mixed to the set speed;
        what remains is its temperature: water's speed changes by ≈ 2 m/s per °C near 37 °C
        (Del Grosso & Mader 1972), so ±1.5 °C ≈ ±3 m/s ≈ 0.2 %. (Across soft tissues the speed
        spreads 1540–1600 m/s, Duck 1990; the path here is through the solution.)
    clock : float
        Time-of-flight counter step Δ [s]: ``7.8`` ns (Sonometrics' digital sonomicrometer,
        128-MHz counter; 12.4 µm at 1590 m/s).
    frequency : float
        Crystal frequency f [Hz]: λ = c/f. Tuna §III-A: the 250-µm absolute accuracy is
        "approximately a one-fourth wavelength", so λ = 1 mm and f = 1.59 MHz.
    orientation_error : bool
        Model the leading-edge / orientation error δ_i (bounded by λ/4).
    range_noise : float
        σ_r of the white crystal-geometry error w_i on each range [m]: 88 µm. Sized from Tuna
        §III-B, not fitted to a result: the recorded POI motion is "approximated with an error
        less than 140 µm RMS with frequency components up to 26 Hz", so the recordings held
        at most 0.14 mm RMS above 26 Hz. The white term alone is put at 0.12 mm there, the
        middle of 0.10–0.14 mm, which leaves the rest of that residual (the motion's own
        content above 26 Hz, the counter step) inside the bound. White noise of σ_r per range
        gives σ_r·G per position (3-D; G = ‖:func:`~rhmpc.sim.sensors.trilateration.dilution`‖ =
        √trace((HᵀH)⁻¹) = ``1.534`` for the default crystals at rest, H the unit lines of sight),
        of which the share √(1 − 2·26/f_s) lies above 26 Hz:
        σ_r = 0.12 mm / (``1.534`` · √(1 − 52/257)) = 88 µm at 257 Hz (0.125 mm above 26 Hz at
        404 Hz). 0 disables it.
    tilt_lever : float
        L [m]: the POI crystal's axis turns by d⊥/L rad with the displacement d⊥ across it;
        30 mm, the heart's radius (a wall point turning about the ventricle's centre).
    slip_rate : float
        Cycle slips (echo outliers) per second [1/s]: 0.05 (Tuna §III-A: "occasionally occur
        as a result of ultrasound echoing effects"; the rate is not published).
    slip_duration : tuple of float
        (min, max) length of a slip [s]: 2–8 ms, one to three samples at 257–404 Hz.
    dropouts : Dropouts or None
        Missing samples (none by default: the balloon keeps a line of sight, §III-A).
    latency : float
        Delivery delay [s] (0: Tuna's data were prerecorded).
    upsample : Upsample or None
        Delivery to the control rate (:mod:`rhmpc.sim.sensors.playback`).
    """

    rate: float = 257.0
    crystals: CrystalArray = field(default_factory=CrystalArray)
    sound_speed: float = 1590.0
    sound_speed_error: float = 0.002
    clock: float = 7.8e-9
    frequency: float = 1.59e6
    orientation_error: bool = True
    range_noise: float = 88e-6
    tilt_lever: float = 30e-3
    slip_rate: float = 0.05
    slip_duration: tuple[float, float] = (2e-3, 8e-3)
    dropouts: Dropouts | None = None
    latency: float = 0.0
    upsample: Upsample | None = None

    def __post_init__(self) -> None:
        positive = ("rate", "sound_speed", "frequency", "tilt_lever")
        for name in (*positive, "sound_speed_error", "clock", "slip_rate", "latency",
                     "range_noise"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"sonomicrometry {name} must be finite, got {value}")
            if value < 0 or (name in positive and value == 0):
                raise ValueError(f"sonomicrometry {name} must be "
                                 f"{'> 0' if name in positive else '≥ 0'}, got {value}")
        lo, hi = self.slip_duration
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
            raise ValueError("slip_duration must be (min, max) with 0 < min ≤ max [s]")

    @property
    def wavelength(self) -> float:
        """λ = c / f [m]."""
        return self.sound_speed / self.frequency


@dataclass(frozen=True)
class Sonomicrometer:
    """The measuring stage: true positions in, trilaterated positions out (module equations)."""

    #: Samples measured per block (memory bound; the result does not depend on it).
    BLOCK: ClassVar[int] = 1 << 15

    settings: SonomicrometrySettings = field(default_factory=SonomicrometrySettings)

    def slips(self, t: np.ndarray, count: int,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(start [s], length [s], crystal index) of the cycle slips over the samples ``t``."""
        cfg = self.settings
        span = float(t[-1] - t[0]) if t.size else 0.0
        n = rng.poisson(cfg.slip_rate * span)
        start = np.sort(rng.uniform(t[0], t[0] + span, n)) if n else np.empty(0)
        return start, rng.uniform(*cfg.slip_duration, n), rng.integers(0, count, n)

    def paths(self, x: np.ndarray, d_perp: np.ndarray) -> np.ndarray:
        """Acoustic paths d_i + δ_i (n, m) [m] of POI positions ``x`` (n, 3), displacements
        across the POI axis ``d_perp`` (n, 3)."""
        cfg = self.settings
        dist, line = self._lines(x)
        travel = dist.copy()
        if cfg.orientation_error:
            n0 = -cfg.crystals.poi() / np.linalg.norm(cfg.crystals.poi())  # facing the base
            axis = n0[None, :] + d_perp / cfg.tilt_lever
            axis /= np.linalg.norm(axis, axis=1, keepdims=True)
            gain = self._obliquity(axis, line)
            rest = self._obliquity(n0[None, :], self._lines(cfg.crystals.poi()[None, :])[1])
            travel += cfg.wavelength / 4.0 * (rest - gain)  # offset calibrated at rest
        return travel

    @staticmethod
    def _obliquity(axis: np.ndarray, line: np.ndarray) -> np.ndarray:
        """cos θ_i · cos φ_i ∈ [0, 1]: POI crystal axis against the line of sight to crystal i,
        and crystal i's axis (the base's normal, +z) against the line back to the POI."""
        cos_poi = np.clip(np.einsum("nk,nmk->nm", axis, line), 0.0, 1.0)
        return cos_poi * np.clip(-line[:, :, 2], 0.0, 1.0)

    def _lines(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distances (n, m), unit vectors (n, m, 3)) from POI positions ``x`` to the crystals."""
        diff = self.settings.crystals.positions()[None, :, :] - x[:, None, :]
        dist = np.linalg.norm(diff, axis=2)
        return dist, diff / dist[:, :, None]

    def quantize(self, path: np.ndarray, scale: float) -> np.ndarray:
        """r = c·Δ·round(path/(c(1+ε))/Δ): the counter's step on the time of flight [m]."""
        cfg = self.settings
        tof = path / (cfg.sound_speed * scale)
        if cfg.clock > 0:
            tof = cfg.clock * np.round(tof / cfg.clock)
        return cfg.sound_speed * tof

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        """Measure the whole run: the run's draws first (speed-of-sound error, slips), then the
        ranges and the trilateration block by block (:data:`BLOCK` samples), so that memory
        does not grow with the run's length beyond the stream itself; the result does not
        depend on the block size (each sample is solved on its own, the white range errors are
        drawn block after block from one stream of normal deviates)."""
        cfg = self.settings
        if stream.t.size == 0:
            return stream
        dim = stream.dim
        if dim > 3:
            raise ValueError("sonomicrometry measures at most 3 axes")
        n = stream.t.size
        p = np.zeros((n, 3))
        p[:, :dim] = stream.z
        finite = np.isfinite(p).all(axis=1)
        anchor = p[np.argmax(finite)] if finite.any() else np.zeros(3)
        x0 = cfg.crystals.poi()
        n0 = x0 / np.linalg.norm(x0)
        scale = 1.0 + cfg.sound_speed_error * rng.standard_normal()
        start, length, which = self.slips(stream.t, cfg.crystals.positions().shape[0], rng)
        bounds = np.searchsorted(stream.t, np.stack([start, start + length], axis=1))
        z = np.empty((n, dim))
        for a in range(0, n, self.BLOCK):
            b = min(a + self.BLOCK, n)
            d = p[a:b] - anchor
            d_perp = d - np.outer(d @ n0, n0)
            path = self.paths(x0 + d, d_perp)
            if cfg.range_noise > 0:
                path += cfg.range_noise * rng.standard_normal(path.shape)
            for (i0, i1), i in zip(bounds, which, strict=True):
                lo, hi = max(i0, a), min(max(i1, i0 + 1), b)
                if lo < hi:
                    path[lo - a:hi - a, i] += cfg.wavelength * scale  # one cycle late
            r = self.quantize(path, scale)
            x_hat = trilaterate(cfg.crystals.positions(), r, side=x0)
            z[a:b] = (x_hat - x0 + anchor)[:, :dim]
        return replace(stream, z=z)


def sonomicrometry(settings: SonomicrometrySettings | None = None, dim: int = 3) -> Sensor:
    """The physical sonomicrometer: sample, measure (module equations), dropouts, latency,
    delivery. ``dim`` < 3: the motion runs along the first axes of the base's frame."""
    cfg = settings or SonomicrometrySettings()
    if dim > 3:
        raise ValueError("sonomicrometry measures at most 3 axes")
    return Sensor(cfg.rate, (Sonomicrometer(cfg), *delivery_stages(cfg)), "sonomicrometry")
