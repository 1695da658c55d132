"""Prediction studies: Yuen et al. 2008 §III-D (Tuna 2013 §VIII-C, Figs 12–13) and Tuna Fig. 8.

``noise``    mitral-1d at 60 bpm, 28 Hz, white noise σ_R ∈ [0.3, 3] mm; 30 s to initialise,
             then the RMS of the one-sample-ahead error against the truth over 10 s.
``hr-step``  as ``noise`` with σ_R = 1.3 mm, but the last 10 s run at base + ΔHR bpm,
             ΔHR ∈ [−10, 10] bpm (the trajectory compressed/dilated beat by beat); base
             60 bpm (Yuen's protocol, ``paper="yuen2008"``, the default) or 103 bpm
             (Tuna §VIII-D, ``paper="tuna2013"``).
``rr``       as ``hr-step`` but the heart phase follows the beat annotations of PhysioNet
             records (a random 45 s stretch per trial; by default the records shipped with
             the package), the analogue of Yuen's Table I.
``horizon``  RMS error versus lead time (Tuna Fig. 8) for sonomicrometry replicas sampled at
             the MPC's predictor period 7.5 ms (σ = 0.25 mm/√3 per axis, no echo outliers),
             40 s of warm-up (the EKF needs 10 s) and 20 s of evaluation; by default two
             replicas and the in-vivo regime (its motion through the same sensor).

Each trial draws its scenario phase and its noise from its own generator, spawned from
the study seed (``SeedSequence(seed).spawn``); every predictor and every parameter value of
a trial sees the same draw (common random numbers), so differences between columns are
not sampling noise.  Errors are Euclidean norms, reported in millimetres.

EKF parameters follow Yuen: ``yuen2008`` with σ_R set to the simulated noise; in ``hr-step``
and ``rr`` q_ω = 5e-3 (rad/s)² and σ_ω² = 1 (rad/s)² (Yuen §III-D).  The RLS predictors run
with order N = 30 at 28 Hz (Tuna Figs 12–13 compare them at the AR filter's order 30; their
133 Hz orders 16/10 span too short a history at 28 Hz).  ``last-cycle`` is Yuen's
(``params="yuen2008"``), synchronised on the beat times of the simulated heart (Yuen and
Bebek synchronise it on the ECG).
``wflc`` runs Yuen's algorithm (``params="yuen2009"``, :meth:`rhmpc.predictors.wflc.WFLCSettings.
yuen2009`: the μ₀ gradient frequency update, no respiratory series), not the 3-D default's
phase-locked loop, whose 0.5 Hz bandwidth passes the noise at 28 Hz and σ_R = 1.3 mm.  In
``horizon`` the predictors that estimate the heart rate (``heart_rate_hz``) are also scored
on ``|ω̂/2π − f_h|`` [beats/min] against the scenario's true rate after the warm-up.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass

import numpy as np

from rhmpc.predictors import make_predictor

__all__ = [
    "BASE_BPM",
    "DEFAULT_PREDICTORS",
    "SCHEMA",
    "STUDIES",
    "StudySettings",
    "run_study",
    "study_settings",
]

#: The version of a study's document (docs/guide/json.md); a change to its keys bumps it.
SCHEMA = "rhmpc.predict.study/1"
STUDIES: tuple[str, ...] = ("noise", "hr-step", "rr", "horizon")
#: hr-step base rate by protocol [beats/min]: Yuen 2008 §III-D, Tuna 2013 §VIII-D
BASE_BPM: dict[str, float] = {"yuen2008": 60.0, "tuna2013": 103.0}
#: RLS order at the 28 Hz of the Yuen studies (Tuna Figs 12–13)
ORDER_28HZ = 30

DEFAULT_PREDICTORS: dict[str, tuple[str, ...]] = {
    "noise": ("ekf", "ar", "fading-ar", "last-cycle", "wflc", "one-step", "generalized"),
    "hr-step": ("ekf", "ar", "fading-ar", "last-cycle", "wflc", "one-step", "generalized"),
    "rr": ("ekf", "ar", "fading-ar", "last-cycle", "wflc", "one-step", "generalized"),
    "horizon": ("one-step", "generalized", "ekf", "dual-ekf", "last-cycle", "hold", "exact"),
}
DEFAULT_TRIALS = {"noise": 100, "hr-step": 100, "rr": 100, "horizon": 10}

MM = 1e-3
YUEN_RATE = 28.0  # Hz, 3DUS
INIT_S, EVAL_S = 30.0, 10.0
HORIZON_DT = 0.0075  # s, 2 kHz / 15
HORIZON_LEADS = 8  # predictor samples: 7.5 … 60 ms
HORIZON_WARM_S, HORIZON_EVAL_S = 40.0, 20.0


@dataclass(frozen=True)
class StudySettings:
    """One prediction study.

    Attributes
    ----------
    study : str
        One of :data:`STUDIES`.
    trials : int
        Monte Carlo trials per parameter value.
    seed : int
        Seed of the study's ``SeedSequence``.
    predictors : tuple of str
        Predictor names (:func:`rhmpc.predictors.make_predictor`).
    noise_mm : tuple of float
        σ_R values of the ``noise`` study [mm].
    delta_bpm : tuple of float
        ΔHR values of the ``hr-step`` study [bpm].
    sigma_mm : float
        Noise of ``hr-step`` and ``rr`` [mm].
    records : tuple of str
        PhysioNet records driving ``rr``: shipped names (``mitdb-100``, ``1003``) or paths
        without extension; empty = every shipped record.
    scenarios : tuple of str
        Scenarios of the ``horizon`` study.
    paper : str
        hr-step protocol, a key of :data:`BASE_BPM` (base heart rate 60 or 103 bpm).
    """

    study: str
    trials: int = 100
    seed: int = 0
    predictors: tuple[str, ...] = ()
    noise_mm: tuple[float, ...] = (0.3, 0.6, 1.0, 1.3, 1.6, 2.0, 2.5, 3.0)
    delta_bpm: tuple[float, ...] = (-10.0, -6.0, -2.0, 0.0, 2.0, 6.0, 10.0)
    sigma_mm: float = 1.3
    records: tuple[str, ...] = ()
    scenarios: tuple[str, ...] = ("fixed-a2-top", "varying-a3-top", "invivo-video")
    paper: str = "yuen2008"

    def __post_init__(self) -> None:
        if self.paper not in BASE_BPM:
            raise ValueError(f"unknown paper {self.paper!r}; valid: {', '.join(BASE_BPM)}")
        if self.study not in STUDIES:
            raise ValueError(f"unknown study {self.study!r}; valid: {', '.join(STUDIES)}")
        if int(self.trials) != self.trials or self.trials < 1:
            raise ValueError(f"trials must be a positive integer, got {self.trials!r}")

    @property
    def names(self) -> tuple[str, ...]:
        return self.predictors or DEFAULT_PREDICTORS[self.study]

    def parameters(self) -> list:
        """The swept values: σ_R [mm], ΔHR [bpm], record paths, or scenario names."""
        if self.study == "noise":
            return list(self.noise_mm)
        if self.study == "hr-step":
            return list(self.delta_bpm)
        if self.study == "rr":
            return list(self.records or default_records())
        return list(self.scenarios)


def study_settings(study: str, trials: int | None = None, seed: int = 0,
                   paper: str = "yuen2008", predictors: tuple[str, ...] = (),
                   noise_mm: tuple[float, ...] = (), delta_bpm: tuple[float, ...] = (),
                   records: tuple[str, ...] = (), scenarios: tuple[str, ...] = ()
                   ) -> StudySettings:
    """The settings of ``study``, each name checked (a one-line :class:`UsageError` naming the
    valid ones); an empty value keeps the study's default (``trials``: :data:`DEFAULT_TRIALS`).
    """
    from rhmpc.errors import UsageError
    from rhmpc.predictors import PREDICTORS

    trials = DEFAULT_TRIALS[study] if trials is None else trials
    if trials < 1:
        raise UsageError(f"--trials must be >= 1, got {trials}")
    kw: dict = {"study": study, "trials": trials, "seed": seed, "paper": paper}
    if bad := [n for n in predictors if n not in PREDICTORS]:
        raise UsageError(f"unknown predictor(s) {', '.join(bad)}; valid: {', '.join(PREDICTORS)}")
    if "exact" in predictors and study != "horizon":
        raise UsageError("`exact` only makes sense in --study horizon")
    if missing := [r for r in records if not _is_record(r)]:
        raise UsageError(f"record(s) not found: {', '.join(missing)} (shipped: "
                         f"{', '.join(default_records())}, or a path without extension)")
    if scenarios:
        from rhmpc.sim.heart import SCENARIOS

        if bad := [s for s in scenarios if s not in SCENARIOS]:
            raise UsageError(f"unknown scenario(s) {', '.join(bad)}; valid: "
                             f"{', '.join(SCENARIOS)}")
    given = {"predictors": predictors, "noise_mm": noise_mm, "delta_bpm": delta_bpm,
             "records": records, "scenarios": scenarios}
    s = StudySettings(**kw, **{k: v for k, v in given.items() if v})
    if study == "rr" and not s.parameters():
        raise UsageError("--study rr needs --records (no shipped record found)")
    return s


def _is_record(name: str) -> bool:
    """Whether ``name`` resolves to a PhysioNet record (a path or a shipped name)."""
    from rhmpc.sim.heart.rr import find_record

    try:
        find_record(name)
    except ValueError:
        return False
    return True


def default_records() -> tuple[str, ...]:
    """The names of the PhysioNet annotation records shipped with the package
    (:func:`rhmpc.sim.heart.rr.shipped_records`: ``1003``, ``mitdb-100``)."""
    from rhmpc.sim.heart.rr import shipped_records

    return tuple(shipped_records())


# -- one trial ----------------------------------------------------------------------------
def _yuen_predictor(
    name: str, dt: float, sigma: float, varying: bool, beats: np.ndarray, t0: float
):
    if name == "ekf":
        extra = {"q_omega": 5e-3, "sigma_omega_sq": 1.0} if varying else {}
        return make_predictor(name, dt, params="yuen2008", sigma_r=sigma, **extra)
    if name in ("one-step", "generalized"):
        return make_predictor(name, dt, order=ORDER_28HZ)
    if name == "last-cycle":
        return make_predictor(name, dt, params="yuen2008", beat_times=tuple(beats), t0=t0)
    if name == "wflc":  # Yuen's gradient WFLC; the PLL default is for 3-D with breathing
        return make_predictor(name, dt, params="yuen2009")
    return make_predictor(name, dt)


def _one_step_rms(pred, z: np.ndarray, truth: np.ndarray, first: int) -> tuple[float, float]:
    """Feed ``z`` (T, d); RMS and max of ‖ẑ_{k+1|k} − p_{k+1}‖ for k + 1 ≥ first [m]."""
    err = np.empty(len(z) - first)
    for k in range(len(z) - 1):
        pred.update(z[k])
        if k + 1 >= first:
            err[k + 1 - first] = np.linalg.norm(pred.predict(1)[0] - truth[k + 1])
    return float(np.sqrt(np.mean(err**2))), float(err.max())


def _mitral_trial(param, study: str, trial_seed: np.random.SeedSequence, s: StudySettings):
    from rhmpc.sim.heart import beat_times_from_annotations, make_scenario
    from rhmpc.sim.sensors import Sensor, WhiteNoise

    rng_scn, rng_noise = (np.random.default_rng(c) for c in trial_seed.spawn(2))
    dur = INIT_S + EVAL_S
    if study == "noise":
        sigma = float(param) * MM
        scn = make_scenario("mitral-1d", rng=rng_scn, beat_gain_std=0.0, duration=dur)
    elif study == "hr-step":
        sigma = s.sigma_mm * MM
        first = -rng_scn.random()  # random phase: a beat in (−1, 0] s
        base = BASE_BPM[s.paper]
        slow = first + np.arange(0.0, INIT_S + 2.0, 60.0 / base)
        slow = slow[slow <= INIT_S]
        fast = slow[-1] + np.arange(1.0, 80.0) * 60.0 / (base + float(param))
        beats = np.concatenate([slow, fast[fast <= dur + 3.0]])
        scn = make_scenario(
            "mitral-1d", rng=rng_scn, beat_gain_std=0.0, beat_times=beats, duration=dur
        )
    else:  # rr: a random stretch of the record's beats
        sigma = s.sigma_mm * MM
        beats = beat_times_from_annotations(param)
        span = dur + 5.0
        start = rng_scn.uniform(beats[0], max(beats[0], beats[-1] - span))
        sel = beats[(beats >= start - 3.0) & (beats <= start + span)]
        scn = make_scenario(
            "mitral-1d", rng=rng_scn, beat_gain_std=0.0, beat_times=sel - start, duration=dur
        )
    stream = Sensor(YUEN_RATE, (WhiteNoise(sigma),), "3DUS").measure(scn.source, dur, rng_noise)
    beats = scn.source.phase.beat_times(-5.0, dur + 5.0)  # the simulated ECG's R waves
    truth = np.asarray(scn.source.position(stream.t)).reshape(len(stream), -1)
    first = round(INIT_S * YUEN_RATE)
    out = {}
    for name in s.names:
        pred = _yuen_predictor(name, 1.0 / YUEN_RATE, sigma, study != "noise", beats, stream.t[0])
        rms, mx = _one_step_rms(pred, stream.z, truth, first)
        out[name] = {"rms": rms, "max": mx}
    return out


def _horizon_trial(param, study: str, trial_seed: np.random.SeedSequence, s: StudySettings):
    from rhmpc.sim.heart import make_scenario
    from rhmpc.sim.sensors import SonomicrometrySettings, sonomicrometry

    rng_scn, rng_noise = (np.random.default_rng(c) for c in trial_seed.spawn(2))
    dur = HORIZON_WARM_S + HORIZON_EVAL_S
    scn = make_scenario(str(param), rng=rng_scn, duration=dur + 1.0)
    sensor = sonomicrometry(
        SonomicrometrySettings(rate=1.0 / HORIZON_DT, slip_rate=0.0), dim=scn.dim
    )
    stream = sensor.measure(scn.source, dur, rng_noise)
    K = HORIZON_LEADS
    t_ext = stream.t[0] + HORIZON_DT * np.arange(len(stream) + K)
    truth = np.asarray(scn.source.position(t_ext)).reshape(t_ext.size, -1)
    first = round(HORIZON_WARM_S / HORIZON_DT)
    true_rate = np.asarray(scn.source.phase.rate(stream.t), dtype=float)
    out = {}
    for name in s.names:
        kw = {"source": scn.source} if name == "exact" else {}
        pred = make_predictor(name, HORIZON_DT, **kw)
        sq = np.zeros(K)
        hr_err = []
        for k in range(len(stream)):
            pred.update(stream.z[k])
            if k >= first:
                e = pred.predict(K) - truth[k + 1 : k + 1 + K]
                sq += np.einsum("ij,ij->i", e, e)
                hr = getattr(pred, "heart_rate_hz", None)
                if hr is not None:
                    hr_err.append(60.0 * abs(hr - true_rate[k]))
        rms = np.sqrt(sq / (len(stream) - first))
        out[name] = {"rms_by_lead": rms.tolist()}
        if hr_err:
            out[name]["hr_err_bpm_max"] = float(np.max(hr_err))
            out[name]["hr_err_bpm_rms"] = float(np.sqrt(np.mean(np.square(hr_err))))
    return out


def _run_task(args: tuple) -> tuple[int, int, dict]:
    i, j, param, study, trial_seed, s = args
    fn = _horizon_trial if study == "horizon" else _mitral_trial
    return i, j, fn(param, study, trial_seed, s)


# -- the study -----------------------------------------------------------------------------
def run_study(
    s: StudySettings,
    jobs: int = 1,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Run all trials (in a process pool when ``jobs > 1``) and aggregate them.

    Returns a JSON-ready dict: ``settings``, ``parameters``, ``unit``, ``rows`` (one per
    parameter value and predictor: mean and standard deviation over trials of the RMS and
    max error [mm], or the RMS per lead for ``horizon``), ``elapsed_s``, ``versions``.
    """
    params = s.parameters()
    if not params:
        raise ValueError(f"study {s.study!r} has nothing to run (no records found?)")
    seeds = np.random.SeedSequence(s.seed).spawn(s.trials)
    tasks = [(i, j, p, s.study, seeds[j], s) for i, p in enumerate(params) for j in range(s.trials)]
    results: dict[tuple[int, int], dict] = {}
    t0 = time.perf_counter()
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for n, (i, j, r) in enumerate(pool.map(_run_task, tasks, chunksize=1), 1):
                results[i, j] = r
                if progress:
                    progress(n, len(tasks))
    else:
        for n, task in enumerate(tasks, 1):
            i, j, r = _run_task(task)
            results[i, j] = r
            if progress:
                progress(n, len(tasks))
    rows = []
    for i, p in enumerate(params):
        for name in s.names:
            per = [results[i, j][name] for j in range(s.trials)]
            row = {"parameter": p, "predictor": name}
            if s.study == "horizon":
                lead = np.array([r["rms_by_lead"] for r in per]) / MM
                row["lead_ms"] = (HORIZON_DT * 1e3 * np.arange(1, HORIZON_LEADS + 1)).tolist()
                row["rms_mm"] = lead.mean(axis=0).tolist()
                row["rms_std_mm"] = lead.std(axis=0).tolist()
                if "hr_err_bpm_max" in per[0]:
                    row["hr_err_bpm_max"] = float(max(r["hr_err_bpm_max"] for r in per))
                    row["hr_err_bpm_rms"] = float(np.mean([r["hr_err_bpm_rms"] for r in per]))
            else:
                rms = np.array([r["rms"] for r in per]) / MM
                mx = np.array([r["max"] for r in per]) / MM
                row.update(
                    rms_mm=float(rms.mean()), rms_std_mm=float(rms.std()), max_mm=float(mx.mean())
                )
            rows.append(row)
    settings = asdict(s)
    settings["predictors"] = list(s.names)
    return {
        "schema": SCHEMA,
        "study": s.study,
        "settings": settings,
        "parameters": [str(p) if s.study == "rr" else p for p in params],
        "rows": rows,
        "elapsed_s": time.perf_counter() - t0,
        "versions": _versions(),
    }


def _versions() -> dict:
    import scipy

    import rhmpc

    return {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "rhmpc": rhmpc.__version__,
    }


def parse_float_list(text: str) -> tuple[float, ...]:
    """'0.3,1,3' → (0.3, 1.0, 3.0); raises ValueError."""
    vals = tuple(float(x) for x in text.split(",") if x.strip())
    if not vals or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"expected a comma-separated list of numbers, got {text!r}")
    return vals
