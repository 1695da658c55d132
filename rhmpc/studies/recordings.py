"""Every predictor on a user's recordings, open loop, each at the recording's own rate.

Each predictor is built with ``make_predictor(name, dt=Δ)``, Δ = 1/rate the file's median
sample period, and sees every raw sample once, in order (a missing sample, NaN or a gap in
the timestamps, is fed as missing). After every update n past the warm-up it forecasts
ẑ_{n+1|n} … ẑ_{n+K|n}; the error at lead k is e_k(n) = ‖ẑ_{n+k|n} − z_{n+k}‖, scored where
z_{n+k} was measured. Reported per lead: RMS and max of e_k [mm], the ratio of the RMS to
the hold forecast's (ẑ_{n+k|n} = z_n) at the same lead, and the predictor's events over the
scored part.

Rules
-----
Warm-up
    The first max(10 s, 25 % of the recording) are excluded (``warmup`` overrides it): the
    predictors converge there, as the closed loop's settling time lets them.
Lead the closed loop needs
    K_loop = ⌈(Δ + λ + N·Ts) / Δ⌉ samples: the forecast made from a sample serves the loop
    until the next sample arrives, one period Δ later plus the delivery latency λ, and must
    reach the MPC's horizon N·Ts (25 ms) beyond that. At 25 Hz: ⌈(40 + 0 + 25)/40⌉ = 2.
Events
    ``rejected``: samples the predictor's own gate refused (``innovation_rejected``, the
    Fourier EKFs); ``repaired``: forecasts its divergence guard repaired (``forecast_clamped``,
    ``forecast_nonfinite``) and samples it retracted (``retracted``); ``missing``: samples
    fed as missing. The closed loop's outlier gate is not part of the open loop.
Several points
    A file of several tracked points (:mod:`sim.recordings.points`) is scored point by point;
    with ``mean`` the study adds a row per predictor and lead whose errors are the means over
    the points.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from predictors import PREDICTORS, make_predictor
from sim.recordings import RecordedMotion, load_points
from sim.recordings.points import pick_point

#: The baselines, first in every table: the newest sample held, and the previous cycle.
BASELINES: tuple[str, ...] = ("hold", "last-cycle")
#: Leads 1 … DEFAULT_LEADS are scored [samples].
DEFAULT_LEADS = 5
#: Warm-up: the longer of this many seconds [s] …
WARMUP_SECONDS = 10.0
#: … and this fraction of the recording [-].
WARMUP_FRACTION = 0.25
#: Counter names of the predictors summed into ``rejected`` and ``repaired``.
REJECTED = ("innovation_rejected", "outliers_rejected")
REPAIRED = ("forecast_clamped", "forecast_nonfinite", "retracted")


def default_predictors() -> tuple[str, ...]:
    """The baselines, then every other registered predictor (the oracle ``exact`` left out)."""
    return (*BASELINES, *(n for n in PREDICTORS if n not in BASELINES and n != "exact"))


@dataclass(frozen=True)
class OpenLoopSettings:
    """How the open-loop scoring runs.

    Attributes
    ----------
    predictors : tuple[str, ...]
        Predictor names (``predictors.PREDICTORS``, not ``exact``); empty = every one.
    leads : int
        L: leads 1 … L are scored, and the closed loop's lead K_loop [samples].
    warmup : float | None
        Seconds excluded from the start of each recording [s]; ``None`` = the longer of
        WARMUP_SECONDS and WARMUP_FRACTION of the recording.
    latency : float
        λ, the delivery latency of the samples to the controller [s] (0: each sample is
        available at its timestamp).
    horizon : float
        N·Ts, the MPC's reach beyond the newest tick [s] (50 × 0.5 ms).
    """

    predictors: tuple[str, ...] = ()
    leads: int = DEFAULT_LEADS
    warmup: float | None = None
    latency: float = 0.0
    horizon: float = 0.025

    def __post_init__(self) -> None:
        bad = [n for n in self.predictors if n not in PREDICTORS or n == "exact"]
        if bad:
            valid = ", ".join(default_predictors())
            raise ValueError(f"unknown predictor(s) {', '.join(bad)}; valid: {valid}")
        if isinstance(self.leads, bool) or not isinstance(self.leads, int) or self.leads < 1:
            raise ValueError(f"leads must be an integer >= 1, got {self.leads!r}")
        if self.warmup is not None and not (math.isfinite(self.warmup) and self.warmup >= 0):
            raise ValueError(f"the warm-up must be >= 0 [s], got {self.warmup!r}")
        if not (math.isfinite(self.latency) and self.latency >= 0):
            raise ValueError(f"the latency must be >= 0 [s], got {self.latency!r}")
        if not (math.isfinite(self.horizon) and self.horizon > 0):
            raise ValueError(f"the horizon must be > 0 [s], got {self.horizon!r}")

    @property
    def names(self) -> tuple[str, ...]:
        return self.predictors or default_predictors()


@dataclass(frozen=True)
class Track:
    """One trajectory to score: a recording, or one tracked point of it.

    Attributes
    ----------
    label : str
        How tables and the JSON name it (``rec.csv``, ``rec.mat:p2``).
    t : ndarray, shape (n,)
        Sample times [s], increasing.
    z : ndarray, shape (n, d)
        Positions [m]; NaN = missing.
    file : str
        The file it came from.
    point : int | None
        Its point number in a file of several (from 1).
    """

    label: str
    t: np.ndarray
    z: np.ndarray
    file: str = ""
    point: int | None = None

    @property
    def period(self) -> float:
        """Δ, the median sample interval [s] (to 12 significant digits: timestamps written in
        decimal make 1/25 s 0.03999999999999915)."""
        return _digits(float(np.median(np.diff(self.t))))


def _digits(x: float) -> float:
    """``x`` to 12 significant digits."""
    return float(f"{x:.12g}")


def parse_points(text: str | None) -> str | tuple[int, ...] | None:
    """``--points``: ``None`` (one-point files), ``"all"``, or point numbers from 1 (``"1,3"``)."""
    if text is None or text.strip().lower() == "all":
        return None if text is None else "all"
    try:
        numbers = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        numbers = ()
    if not numbers or min(numbers) < 1:
        raise ValueError(f"--points {text!r}: expected all or point numbers from 1 (e.g. 1,3)")
    return numbers


def _labels(files: Sequence[str]) -> list[str]:
    """A label per file: its name, or the path as given where two names collide."""
    names = [Path(f).name for f in files]
    return [n if names.count(n) == 1 else str(f) for n, f in zip(names, files, strict=True)]


def file_points(files: Sequence[str], points, read: dict) -> list[list[tuple[str, str, int | None,
                                                                             RecordedMotion]]]:
    """Per file, its (label, file, point, recording) to score: every point or the chosen ones
    (``points`` from :func:`parse_points`); ``point`` is ``None`` in a one-point file.

    Raises
    ------
    ValueError
        A file that cannot be read, a point it lacks, or several points and no ``points``.
    """
    out = []
    for label, f in zip(_labels(files), files, strict=True):
        recordings = load_points(f, **read)
        several = len(recordings) > 1
        if several and points is None:
            raise ValueError(f"{f}: holds {len(recordings)} tracked points; choose them with "
                             "--points all (or --points 1,3, numbered from 1)")
        chosen = range(1, len(recordings) + 1) if points in (None, "all") else points
        out.append([(f"{label}:p{k}" if several else label, f, k if several else None,
                     pick_point(f, recordings, k)) for k in chosen])
    return out


def load_tracks(files: Sequence[str], points, read: dict) -> list[Track | list[Track]]:
    """The tracks of ``files`` for :func:`run_open_loop`: a file of several points gives the
    list of its points (scored with their mean), a one-point file its track."""
    out: list[Track | list[Track]] = []
    for group in file_points(files, points, read):
        tracks = [Track(label, rec.t, rec.z, f, k) for label, f, k, rec in group]
        out.append(tracks if group[0][2] is not None else tracks[0])
    return out


def loop_lead(period: float, latency: float, horizon: float) -> int:
    """K_loop = ⌈(Δ + λ + N·Ts)/Δ⌉ [samples] (module docstring), robust to rounding."""
    return max(1, math.ceil((period + latency + horizon) / period - 1e-9))


def warmup_seconds(duration: float, warmup: float | None) -> float:
    """The warm-up [s]: ``warmup``, or max(WARMUP_SECONDS, WARMUP_FRACTION · duration)."""
    if warmup is not None:
        return float(warmup)
    return max(WARMUP_SECONDS, WARMUP_FRACTION * duration)


def on_grid(t: np.ndarray, z: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples on the grid t₀ + jΔ: a gap in the timestamps becomes missing samples.

    Returns the grid's times (m,) and positions (m, d) with NaN rows in the gaps. Timestamps
    too irregular to round to distinct grid slots are kept as they are, one slot each.
    """
    slot = np.rint((t - t[0]) / period).astype(np.int64)
    if slot.size > 1 and np.any(np.diff(slot) < 1):
        return t, z
    grid = np.full((int(slot[-1]) + 1, z.shape[1]), np.nan)
    grid[slot] = z
    return t[0] + period * np.arange(grid.shape[0]), grid


def forecast_errors(name: str, z: np.ndarray, period: float, first: int,
                    depth: int) -> tuple[np.ndarray, dict[str, int]]:
    """e_k(n) [m] for origins n ≥ ``first`` and leads k = 1 … ``depth``, and the events.

    Returns an array (len(z), depth) — NaN where not scored (before ``first``, past the end,
    or a missing target) — and the predictor's counters accumulated from ``first`` on.
    """
    predictor = make_predictor(name, dt=period)
    n_total = z.shape[0]
    forecasts = np.full((n_total, depth, z.shape[1]), np.nan)
    before: dict[str, int] = {}
    for n in range(n_total):
        predictor.update(z[n])
        if n < first:
            continue
        if n == first:
            before = dict(predictor.counts)
        try:
            forecasts[n] = predictor.predict(depth)
        except RuntimeError:  # no valid sample yet
            continue
    errors = np.full((n_total, depth), np.nan)
    for k in range(1, depth + 1):
        miss = forecasts[: n_total - k, k - 1] - z[k:]
        errors[: n_total - k, k - 1] = np.linalg.norm(miss, axis=1)
    counts = {key: int(v - before.get(key, 0)) for key, v in predictor.counts.items()}
    return errors, {k: v for k, v in counts.items() if v}


def _rows(track: Track, name: str, errors: np.ndarray, counts: dict, leads: list[int],
          k_loop: int) -> list[dict]:
    """One result row per lead of predictor ``name`` on ``track``."""
    period = track.period
    out = []
    for k in leads:
        e = errors[:, k - 1]
        e = 1e3 * e[np.isfinite(e)]
        out.append({
            "source": track.label, "predictor": name, "lead_samples": k,
            "lead_s": _digits(k * period),
            "rms_error_mm": float(np.sqrt(np.mean(e**2))) if e.size else None,
            "max_error_mm": float(np.max(e)) if e.size else None,
            "scored": int(e.size), "loop_lead": k == k_loop,
            "rejected": sum(counts.get(c, 0) for c in REJECTED),
            "repaired": sum(counts.get(c, 0) for c in REPAIRED),
            "missing": counts.get("missing", 0), "counts": counts,
        })
    return out


def score_track(track: Track, settings: OpenLoopSettings,
                progress: Callable[[str], None] | None = None) -> tuple[dict, list[dict]]:
    """The source's description and the result rows of every predictor on ``track``.

    Raises
    ------
    ValueError
        The warm-up leaves nothing to score (the message names the lengths).
    """
    period = track.period
    t, z = on_grid(track.t, track.z, period)
    duration = float(track.t[-1] - track.t[0])
    warmup = warmup_seconds(duration, settings.warmup)
    k_loop = loop_lead(period, settings.latency, settings.horizon)
    leads = sorted({*range(1, settings.leads + 1), k_loop})
    first = int(np.searchsorted(t, t[0] + warmup - 1e-9))
    if first + leads[-1] >= t.size:
        raise ValueError(f"{track.label}: lasts {duration:.2f} s; a warm-up of {warmup:.2f} s "
                         f"and a lead of {leads[-1]} samples leave nothing to score "
                         "(shorten it with --warmup)")
    rows: list[dict] = []
    for name in settings.names:
        if progress is not None:
            progress(f"{name} on {track.label}")
        errors, counts = forecast_errors(name, z, period, first, leads[-1])
        rows += _rows(track, name, errors, counts, leads, k_loop)
    _ratios(rows)
    source = {
        "label": track.label, "file": track.file, "point": track.point,
        "rate_hz": _digits(1.0 / period), "period_s": period, "duration_s": duration,
        "samples": int(track.t.size), "missing": int(np.sum(~np.isfinite(z).all(axis=1))),
        "warmup_s": warmup, "loop_lead_samples": k_loop, "loop_lead_s": _digits(k_loop * period),
        "gap_samples": int(t.size - track.t.size),
        "regular": bool(np.allclose(np.diff(t), period, rtol=0.05)),
    }
    for row in rows:
        row["rate_hz"] = source["rate_hz"]
    return source, rows


def _ratios(rows: list[dict]) -> None:
    """``ratio_to_hold``: each row's RMS over hold's at the same source and lead."""
    hold = {(r["source"], r["lead_samples"]): r["rms_error_mm"] for r in rows
            if r["predictor"] == "hold"}
    for r in rows:
        ref = hold.get((r["source"], r["lead_samples"]))
        ok = ref and r["rms_error_mm"] is not None
        r["ratio_to_hold"] = r["rms_error_mm"] / ref if ok else None


def mean_rows(label: str, rows: Sequence[dict]) -> list[dict]:
    """Rows of ``label`` whose errors are the means over the sources of ``rows`` per predictor
    and lead (events summed)."""
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["predictor"], r["lead_samples"]), []).append(r)
    out = []
    for (name, k), group in groups.items():
        rms = [g["rms_error_mm"] for g in group if g["rms_error_mm"] is not None]
        mx = [g["max_error_mm"] for g in group if g["max_error_mm"] is not None]
        out.append({
            "source": label, "predictor": name, "lead_samples": k,
            "lead_s": float(np.mean([g["lead_s"] for g in group])),
            "rms_error_mm": float(np.mean(rms)) if rms else None,
            "max_error_mm": float(np.mean(mx)) if mx else None,
            "scored": sum(g["scored"] for g in group),
            "loop_lead": all(g["loop_lead"] for g in group),
            **{key: sum(g[key] for g in group) for key in ("rejected", "repaired", "missing")},
            "points": len(group), "rate_hz": group[0]["rate_hz"],
        })
    _ratios(out)
    return out


def run_open_loop(tracks: Sequence[Track | list[Track]], settings: OpenLoopSettings,
                  progress: Callable[[str], None] | None = None) -> dict:
    """Score every predictor on every track; a list of tracks (the points of one file) also
    gets its ``mean`` rows, labelled ``FILE:mean``.

    Returns
    -------
    dict
        ``rate_hz`` and ``warmup_s`` (shared by every source, else ``None``), ``sources``
        (one description each), ``results`` (one row per source × predictor × lead:
        ``predictor``, ``lead_samples``, ``lead_s``, ``rms_error_mm``, ``max_error_mm``,
        ``ratio_to_hold``, ``rejected``, ``repaired``, ``missing``, ``loop_lead`` …) and the
        rules (``warmup_rule``, ``loop_lead_rule``).
    """
    sources, results = [], []
    for item in tracks:
        group = item if isinstance(item, list) else [item]
        rows_of_group = []
        for track in group:
            source, rows = score_track(track, settings, progress)
            sources.append(source)
            rows_of_group += rows
        results += rows_of_group
        if isinstance(item, list) and len(group) > 1:
            results += mean_rows(f"{group[0].label.rsplit(':', 1)[0]}:mean", rows_of_group)
    rates = {round(s["rate_hz"], 9) for s in sources}
    warmups = {round(s["warmup_s"], 9) for s in sources}
    return {
        "rate_hz": sources[0]["rate_hz"] if len(rates) == 1 else None,
        "warmup_s": sources[0]["warmup_s"] if len(warmups) == 1 else None,
        "latency_s": settings.latency, "horizon_s": settings.horizon,
        "leads": settings.leads, "predictors": list(settings.names),
        "warmup_rule": "given" if settings.warmup is not None else
        f"max({WARMUP_SECONDS:g} s, {100 * WARMUP_FRACTION:g} % of the recording)",
        "loop_lead_rule": "ceil((period + latency + horizon) / period)",
        "sources": sources, "results": results,
    }


def _lead_head(rows: list[dict], leads: list[int]) -> str:
    period = {r["lead_samples"]: r["lead_s"] for r in rows}
    k_loop = next((r["lead_samples"] for r in rows if r["loop_lead"]), None)
    return "".join(f"{f'{k}/{1e3 * period[k]:.0f}' + ('*' if k == k_loop else ''):>10}"
                   for k in leads)


def _table(rows: list[dict], names: list[str], key: str, extra: bool) -> list[str]:
    """One line per predictor: ``key`` per lead (and the ratios and events if ``extra``)."""
    leads = sorted({r["lead_samples"] for r in rows})
    k_loop = next((r["lead_samples"] for r in rows if r["loop_lead"]), leads[-1])
    by = {(r["predictor"], r["lead_samples"]): r for r in rows}
    head = f"{'predictor':<12}" + _lead_head(rows, leads)
    if extra:
        head += f"{'÷hold 1':>9}{'÷hold *':>9}{'rejected':>10}{'repaired':>10}"
    lines = [head]
    for name in names:
        if (name, leads[0]) not in by:
            continue
        cells = [by[name, k][key] for k in leads]
        line = f"{name:<12}" + "".join(f"{'—':>10}" if v is None else f"{v:>10.3f}"
                                       for v in cells)
        if extra:
            ratios = [by[name, k]["ratio_to_hold"] for k in (leads[0], k_loop)]
            line += "".join(f"{'—':>9}" if v is None else f"{v:>9.2f}" for v in ratios)
            line += f"{by[name, k_loop]['rejected']:>10}{by[name, k_loop]['repaired']:>10}"
        lines.append(line)
    return lines


def _source_line(s: dict, doc: dict) -> str:
    period_ms = 1e3 * s["period_s"]
    gaps = f", {s['gap_samples']} missing between timestamps" if s["gap_samples"] else ""
    rule = ("given" if doc["warmup_rule"] == "given" else "the longer of "
            f"{WARMUP_SECONDS:g} s and {100 * WARMUP_FRACTION:g} % of the recording")
    return (f"{s['label']}: {s['samples']} samples at {s['rate_hz']:.4g} Hz (Δ {period_ms:.3g} "
            f"ms), {s['duration_s']:.1f} s, {s['missing']} missing{gaps}; warm-up "
            f"{s['warmup_s']:.1f} s excluded ({rule}); the closed loop needs lead "
            f"{s['loop_lead_samples']} = {1e3 * s['loop_lead_s']:.0f} ms "
            f"(⌈(Δ + λ + N·Ts)/Δ⌉ = ⌈({period_ms:.3g} + {1e3 * doc['latency_s']:g} + "
            f"{1e3 * doc['horizon_s']:g})/{period_ms:.3g}⌉)")


def format_report(doc: dict) -> str:
    """The open-loop tables of :func:`run_open_loop`: per source, RMS and max error by lead."""
    names = doc["predictors"]
    described = {s["label"]: s for s in doc["sources"]}
    out = []
    for label in dict.fromkeys(r["source"] for r in doc["results"]):
        rows = [r for r in doc["results"] if r["source"] == label]
        if label in described:
            out.append(_source_line(described[label], doc))
        else:
            out.append(f"{label}: the mean over {rows[0]['points']} points")
        out.append("RMS forecast error [mm] at lead [samples/ms] (* the closed loop's lead); "
                   "÷hold: RMS over hold's; events after the warm-up")
        out += _table(rows, names, "rms_error_mm", True)
        out.append("max forecast error [mm]")
        out += _table(rows, names, "max_error_mm", False)
        out.append("")
    return "\n".join(out).rstrip()


def plot_leads(doc: dict, path) -> None:
    """RMS error against lead [ms], every predictor, one panel per source (PNG at ``path``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(dict.fromkeys(r["source"] for r in doc["results"]))
    fig, axes = plt.subplots(len(labels), 1, figsize=(8, 3.6 * len(labels)), squeeze=False)
    for ax, label in zip(axes[:, 0], labels, strict=True):
        rows = [r for r in doc["results"] if r["source"] == label]
        for i, name in enumerate(doc["predictors"]):
            pts = sorted((1e3 * r["lead_s"], r["rms_error_mm"]) for r in rows
                         if r["predictor"] == name and r["rms_error_mm"] is not None)
            if pts:
                x, y = zip(*pts, strict=True)
                style = "--" if name in BASELINES else "-"
                ax.plot(x, y, style, marker="o", ms=3, color=f"C{i % 10}", label=name)
        loop = [1e3 * r["lead_s"] for r in rows if r["loop_lead"]]
        if loop:
            ax.axvline(loop[0], color="0.5", lw=0.8, ls=":", label="closed loop's lead")
        ax.set(xlabel="lead [ms]", ylabel="RMS forecast error [mm]", title=label)
        ax.set_yscale("log")
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
