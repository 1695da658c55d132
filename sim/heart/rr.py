r"""Heart phase: heart-rate profiles, RR intervals and the phase track built from them.

The heart phase φ(t) counts heartbeats (cycles, not radians). Beat *i* starts when φ crosses
the integer *i*. Two ways drive it:

* a heart-rate profile :math:`f_h(t)` [Hz], with
  :math:`\varphi(t) = \varphi(t_0) + \int_{t_0}^{t} f_h(\tau)\,d\tau`. The profile can be
  constant, or the pacemaker staircase of Tuna et al. §III-B;
* a sequence of beat times t_i (from RR intervals). In that case φ(t_i) = i exactly, and φ is
  a monotone cubic (PCHIP) through the points (t_i, i). This is the beat-by-beat
  compression/dilation of one cycle used by Yuen et al., but with a continuous rate.

Both are stored as a piecewise polynomial :class:`PhaseTrack`. It evaluates vectorised, so
one call covers a whole 2 kHz run.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator, PPoly

from rhmpc import io

#: Annotation symbols that mark a heartbeat (PhysioNet/MIT-BIH convention). Premature beats
#: (A, a, J, S, V, F, e, j, n, E) are kept on purpose: they are the arrhythmia events.
BEAT_SYMBOLS: frozenset[str] = frozenset("NLRBAaJSVrFejnE/fQ?")

#: The pacemaker staircase levels of Tuna et al. §III-B, as the spectral peaks they report
#: [Hz] (95, 110, 120, 130, 145 and 152 beats/min).
STAIRCASE_LEVELS_HZ: tuple[float, ...] = (1.58, 1.81, 2.03, 2.18, 2.42, 2.54)


class PhaseTrack:
    """Heart phase φ(t) [cycles] as a piecewise polynomial, with linear extrapolation.

    Inside ``[t_start, t_end]`` the phase is the piecewise polynomial ``poly``. Outside, it
    continues at the end-point rate: φ(t) = φ(t_end) + f_h(t_end)·(t − t_end), and likewise
    before ``t_start``. So the source can be evaluated at any time.

    Parameters
    ----------
    poly : scipy.interpolate.PPoly
        φ(t) on its breakpoints [s → cycles]; must be non-decreasing.
    """

    def __init__(self, poly: PPoly) -> None:
        self._poly = poly
        self._rate = poly.derivative()
        self.t_start = float(poly.x[0])
        self.t_end = float(poly.x[-1])
        self._phi0 = float(poly(self.t_start))
        self._phi1 = float(poly(self.t_end))
        self._f0 = float(self._rate(self.t_start))
        self._f1 = float(self._rate(self.t_end))

    @classmethod
    def from_rate_knots(cls, t: np.ndarray, rate: np.ndarray, phase0: float = 0.0) -> PhaseTrack:
        r"""Phase from a piecewise-linear heart-rate profile.

        .. math::

            \varphi(t) = \varphi_0 + \int_{t_0}^{t} f_h(\tau)\,d\tau,

        integrated exactly (piecewise quadratic).

        Parameters
        ----------
        t : ndarray, shape (m,)
            Strictly increasing knot times [s], m ≥ 2.
        rate : ndarray, shape (m,)
            Heart rate at the knots [Hz], > 0; linear in between.
        phase0 : float
            φ(t₀) [cycles].
        """
        t = np.asarray(t, dtype=float)
        rate = np.asarray(rate, dtype=float)
        if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
            raise ValueError("rate knots need at least two strictly increasing times")
        if rate.shape != t.shape or np.any(~np.isfinite(rate)) or np.any(rate <= 0):
            raise ValueError("heart rate must be finite and positive at every knot")
        slope = np.diff(rate) / np.diff(t)
        linear = PPoly(np.vstack([slope, rate[:-1]]), t)
        phase = linear.antiderivative()
        phase.c[-1] += phase0
        return cls(phase)

    @classmethod
    def from_beat_times(cls, beat_times: np.ndarray, first_beat: int = 0) -> PhaseTrack:
        """Phase through given beat times: φ(t_i) = first_beat + i exactly.

        Between beats the phase is the monotone cubic (PCHIP) through (t_i, i), so the
        instantaneous rate is continuous and each beat lasts exactly its RR interval.

        Parameters
        ----------
        beat_times : ndarray, shape (n,)
            Strictly increasing beat onset times [s], n ≥ 2.
        first_beat : int
            The beat number of ``beat_times[0]``.
        """
        tb = np.asarray(beat_times, dtype=float)
        if tb.ndim != 1 or tb.size < 2:
            raise ValueError("need at least two beat times")
        if np.any(~np.isfinite(tb)) or np.any(np.diff(tb) <= 0):
            raise ValueError("beat times must be finite and strictly increasing")
        idx = first_beat + np.arange(tb.size, dtype=float)
        return cls(_pchip_ppoly(tb, idx))

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        """φ(t) [cycles], same shape as ``t``."""
        t = np.asarray(t, dtype=float)
        inside = np.clip(t, self.t_start, self.t_end)
        outside = t - inside  # < 0 before the start, > 0 after the end, else 0
        return self._poly(inside) + outside * np.where(outside < 0, self._f0, self._f1)

    def rate(self, t: float | np.ndarray) -> np.ndarray:
        """Instantaneous heart rate f_h(t) = dφ/dt [Hz]."""
        t = np.asarray(t, dtype=float)
        return self._rate(np.clip(t, self.t_start, self.t_end))

    def beat_times(self, t0: float, t1: float) -> np.ndarray:
        """Times [s] in ``[t0, t1]`` where φ crosses an integer (beat onsets)."""
        k0 = int(np.ceil(float(self(t0))))
        k1 = int(np.floor(float(self(t1))))
        if k1 < k0:
            return np.empty(0)
        ks = np.arange(k0, k1 + 1, dtype=float)
        # Bisection on the monotone phase, vectorised over all beats.
        lo = np.full(ks.shape, float(t0))
        hi = np.full(ks.shape, float(t1))
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            below = self(mid) < ks
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        return 0.5 * (lo + hi)


def _pchip_ppoly(x: np.ndarray, y: np.ndarray) -> PPoly:
    """The PCHIP interpolant of (x, y) as a :class:`~scipy.interpolate.PPoly`."""
    p = PchipInterpolator(x, y, extrapolate=False)
    return PPoly(p.c, p.x, extrapolate=True)


@dataclass(frozen=True)
class StaircaseProfile:
    """The pacemaker staircase of Tuna et al. §III-B.

    The heart beats ``initial`` seconds at the first level, then steps through the levels up
    to the last one and back down, ``step`` seconds per level, and stays at the first level
    until the end. Rates change linearly over ``transition`` seconds (pacing takes effect
    within a beat or two). A shorter record simply ends part-way through the protocol (with
    the defaults, 140 s end during the descent, after all six levels).

    Attributes
    ----------
    levels : tuple of float
        Heart rates of the steps [Hz], in climbing order.
    initial : float
        Time at the first level before the first step [s].
    step : float
        Time spent at each level [s].
    transition : float
        Duration of the linear ramp between two levels [s].
    """

    levels: tuple[float, ...] = STAIRCASE_LEVELS_HZ
    initial: float = 40.0
    step: float = 15.0
    transition: float = 1.0

    def knots(self, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """Knot times [s] and rates [Hz] of the piecewise-linear profile over ``[0, duration]``."""
        sequence = list(self.levels) + list(self.levels[-2::-1])
        initial, step = self.initial, self.step
        ramp = min(self.transition, 0.5 * step)
        ts, fs = [0.0], [sequence[0]]
        t = initial
        for prev, nxt in itertools.pairwise(sequence):
            ts += [t - 0.5 * ramp, t + 0.5 * ramp]
            fs += [prev, nxt]
            t += step
        end = max(duration, ts[-1] + 1.0)
        ts.append(end)
        fs.append(sequence[-1])
        return np.asarray(ts), np.asarray(fs)


def constant_phase(rate: float, phase0: float = 0.0) -> PhaseTrack:
    """φ(t) = φ₀ + f_h·t for a constant heart rate ``rate`` [Hz]."""
    return PhaseTrack.from_rate_knots(np.array([0.0, 1.0]), np.array([rate, rate]), phase0)


def staircase_phase(profile: StaircaseProfile, duration: float, phase0: float = 0.0) -> PhaseTrack:
    """φ(t) = φ₀ + ∫₀ᵗ f_h(τ) dτ for the pacemaker staircase ``profile`` over ``duration`` [s]."""
    t, f = profile.knots(duration)
    return PhaseTrack.from_rate_knots(t, f, phase0)


def beat_times_from_rr(rr: np.ndarray, start: float = 0.0) -> np.ndarray:
    r"""Beat times :math:`t_0 = \text{start}`, :math:`t_i = \text{start} + \sum_{j<i} RR_j` [s]
    from RR intervals [s]."""
    rr = np.asarray(rr, dtype=float)
    if rr.ndim != 1 or rr.size < 1:
        raise ValueError("need at least one RR interval")
    if np.any(~np.isfinite(rr)) or np.any(rr <= 0):
        raise ValueError("RR intervals must be finite and positive")
    return start + np.concatenate([[0.0], np.cumsum(rr)])


#: The PhysioNet annotation records shipped with the package, one folder each (their source
#: and licence: the folder's README.md).
RECORDS_DIR: Path = Path(__file__).resolve().parent / "physionet"


def shipped_records() -> dict[str, Path]:
    """The shipped records by folder name (``mitdb-100``, ``1003``) → base path (no suffix)."""
    return {atr.parent.name: atr.with_suffix("") for atr in sorted(RECORDS_DIR.glob("*/*.atr"))}


def _shipped_base(name: str) -> Path | None:
    """A shipped record by folder (``mitdb-100``), record (``100``) or both (``mitdb-100/100``)."""
    key = name[: -len(Path(name).suffix)] if Path(name).suffix in {".atr", ".hea"} else name
    for folder, base in shipped_records().items():
        if key in (folder, base.name, f"{folder}/{base.name}"):
            return base
    return None


def find_record(record_path: str | Path) -> Path:
    """The base (path without suffix) of a PhysioNet record.

    Parameters
    ----------
    record_path : str or Path
        ``dir/100``, ``dir/100.atr``/``.hea``, a folder holding exactly one ``.atr`` file, or,
        when no such path exists, the name of a shipped record (:func:`shipped_records`):
        ``mitdb-100``, ``100``, ``mitdb-100/100``, ``1003``.

    Raises
    ------
    ValueError
        Neither a record on disk nor a shipped one (the message lists the shipped names).
    """
    try:
        return _local_base(Path(record_path))
    except ValueError as exc:
        shipped = _shipped_base(str(record_path))
        if shipped is None:
            names = ", ".join(shipped_records())
            raise ValueError(f"{exc} (nor a shipped record: {names})") from None
        return shipped


def _local_base(path: Path) -> Path:
    if path.is_dir():
        atr = sorted(path.glob("*.atr"))
        if len(atr) != 1:
            raise ValueError(f"{path}: expected exactly one .atr annotation file, found {len(atr)}")
        return atr[0].with_suffix("")
    if path.suffix in {".atr", ".hea", ".dat"}:
        path = path.with_suffix("")
    if not path.with_suffix(".atr").is_file():
        raise ValueError(f"{path}: no annotation file {path.with_suffix('.atr').name}")
    return path


def _annotations(base: Path):
    """The record's beat annotations (``wfdb.rdann``), once the one reader has checked its
    ``.atr`` file (a regular file within its size bound, :func:`rhmpc.io.open_input`)."""
    io.open_input(base.with_name(base.name + ".atr"), "annotation file").close()
    with warnings.catch_warnings():  # wfdb's pandas deprecation noise, not ours
        warnings.filterwarnings("ignore", module=r"wfdb(\.|$)")
        import wfdb

        return wfdb.rdann(str(base), "atr")


def beat_times_from_annotations(record_path: str | Path) -> np.ndarray:
    """Beat times [s] of a PhysioNet annotated record (``.atr``), beat symbols only.

    Non-beat annotations (rhythm changes ``+``, noise ``~``, comments...) are skipped.
    Premature beats are kept.

    Parameters
    ----------
    record_path : str or Path
        The record without extension (``.../mitdb-100/100``), its ``.atr``/``.hea`` file, a
        folder that holds exactly one ``.atr`` file, or the name of a shipped record
        (``mitdb-100``, ``1003``: :func:`shipped_records`).
    """
    base = find_record(record_path)
    ann = _annotations(base)
    keep = np.array([s in BEAT_SYMBOLS for s in ann.symbol], dtype=bool)
    samples = np.asarray(ann.sample)[keep]
    if samples.size < 2:
        raise ValueError(f"{base}.atr: fewer than two beat annotations")
    return samples / float(ann.fs)


#: Symbols of premature (ectopic) beats: atrial (A), aberrated atrial (a), nodal (J), supra-
#: ventricular (S), ventricular (V), fusion (F) and ventricular escape (E).
PREMATURE_SYMBOLS: frozenset[str] = frozenset("AaJSVFE")


def beats_from_annotations(record_path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Beat times [s] and a mask of premature beats (:data:`PREMATURE_SYMBOLS`) of a record."""
    base = find_record(record_path)
    ann = _annotations(base)
    symbols = [s for s in ann.symbol if s in BEAT_SYMBOLS]
    keep = np.array([s in BEAT_SYMBOLS for s in ann.symbol], dtype=bool)
    times = np.asarray(ann.sample)[keep] / float(ann.fs)
    return times, np.array([s in PREMATURE_SYMBOLS for s in symbols], dtype=bool)


def rr_from_annotations(record_path: str | Path) -> np.ndarray:
    """RR intervals RR_i = t_{i+1} − t_i [s] between the annotated beats of a record.

    See :func:`beat_times_from_annotations` for which annotations count as beats.
    """
    return np.diff(beat_times_from_annotations(record_path))


@dataclass(frozen=True)
class RRSettings:
    """Synthetic RR-interval generator settings (heart-rate variability).

    The RR tachogram is RR(t) = RR̄ + s_LF(t) + s_HF(t) + w, where s_LF and s_HF are Gaussian
    processes whose spectra are Gaussian bumps at ``lf`` and ``hf`` (Mayer waves and
    respiratory sinus arrhythmia, as in McSharry et al.'s ECG model), and w is white
    beat-to-beat noise.

    Attributes
    ----------
    mean_rate : float
        Mean heart rate 1/RR̄ [Hz] (1.25 Hz = 75 beats/min).
    std : float
        Standard deviation of the RR intervals [s] (SDNN).
    lf : float
        Centre of the low-frequency band [Hz].
    hf : float
        Centre of the high-frequency band [Hz].
    band_width : float
        Standard deviation of each spectral bump [Hz].
    lf_hf_ratio : float
        Power ratio LF/HF [-].
    white_fraction : float
        Fraction of the RR variance that is white beat-to-beat noise [-], in [0, 1].
    min_rr : float
        Lower bound applied to every interval [s].
    """

    mean_rate: float = 1.25
    std: float = 0.05
    lf: float = 0.1
    hf: float = 0.25
    band_width: float = 0.01
    lf_hf_ratio: float = 0.5
    white_fraction: float = 0.1
    min_rr: float = 0.25

    def __post_init__(self) -> None:
        if not self.mean_rate > 0 or not self.std >= 0:
            raise ValueError("mean_rate must be > 0 and std ≥ 0")
        if not 0.0 <= self.white_fraction <= 1.0:
            raise ValueError("white_fraction must be in [0, 1]")


def synthetic_rr(duration: float, rng: np.random.Generator,
                 settings: RRSettings | None = None) -> np.ndarray:
    """Seeded synthetic RR intervals [s] covering at least ``duration`` seconds.

    RR_i = RR̄ + s(t_i) + w_i, with s the LF+HF tachogram of :class:`RRSettings` sampled at the
    beat times t_i and w_i ~ N(0, σ_w²). The variances are split so that std(RR) ≈ ``std``.
    """
    cfg = settings or RRSettings()
    mean_rr = 1.0 / cfg.mean_rate
    fs = 4.0  # tachogram sample rate [Hz]
    n = int(np.ceil((duration + 10 * mean_rr) * fs)) + 16
    n_fft = 1 << int(np.ceil(np.log2(max(n, 64))))
    f = np.fft.rfftfreq(n_fft, 1.0 / fs)

    def bump(centre: float) -> np.ndarray:
        return np.exp(-0.5 * ((f - centre) / cfg.band_width) ** 2)

    amp = np.sqrt(cfg.lf_hf_ratio * bump(cfg.lf) + bump(cfg.hf))
    spec = amp * np.exp(2j * np.pi * rng.random(f.size))
    spec[0] = 0.0
    s = np.fft.irfft(spec, n_fft)[:n]
    s_std = float(np.std(s))
    coloured_std = cfg.std * np.sqrt(1.0 - cfg.white_fraction)
    s = s * (coloured_std / s_std) if s_std > 0 else np.zeros_like(s)
    white_std = cfg.std * np.sqrt(cfg.white_fraction)
    rr: list[float] = []
    t = 0.0
    while t < duration or len(rr) < 1:
        k = min(int(t * fs), n - 1)
        value = mean_rr + s[k] + white_std * rng.standard_normal()
        value = max(value, cfg.min_rr)
        rr.append(value)
        t += value
    return np.asarray(rr)
