"""Running a configured closed loop and the JSON document of its result."""

from __future__ import annotations

import platform
import resource
import sys
import time
import warnings
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import numpy as np

from rhmpc.experiment.assembly import Run, build_run
from rhmpc.experiment.config import RunConfig
from rhmpc.experiment.faults import fault_marks, fault_report
from rhmpc.sim.loop import LoopResult, run_closed_loop
from rhmpc.sim.sensors import DEFAULT_PLAYBACK
from rhmpc.timing.yardstick import GainTick

#: The version of a run's document (docs/guide/json.md); a change to its keys bumps it.
SCHEMA = "rhmpc.simulate/1"


def versions() -> dict[str, str]:
    """Versions of the packages a result depends on."""
    out = {"python": platform.python_version()}
    for name in ("rhmpc", "pin", "osqp", "casadi", "numpy", "scipy"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def run_experiment(config: RunConfig, progress: bool = False, trace: str | None = None,
                   gain_tick: bool = False,
                   implementation: str = "python") -> tuple[LoopResult, dict]:
    """Run ``config`` in closed loop; returns the :class:`~rhmpc.sim.loop.LoopResult` and its
    document.

    The document holds the settings, the metrics (``rms_error_mm``, ``max_error_mm``,
    ``rms_effort_mNm``, ``tick_us`` with ``p50``/``p99``/``max``, ``fallbacks`` …), the wall
    time of the loop (``wall_s``) and of building the run before it (``build_s``: the robot,
    the controller, the fits), the peak resident memory of the process so far
    (``peak_rss_mb``) and the package versions. ``trace``: write every tick to this NPZ
    file (:mod:`rhmpc.sim.loop.trace`).
    ``gain_tick``: time the gain tick g (:class:`~rhmpc.timing.yardstick.GainTick`) in the run
    on every 64th tick, so that the document has ``gain_tick_us`` and the tick's ratios to its
    p50 (``tick_ratio_to_gain``). ``implementation``: ``"python"`` or
    ``"c"`` (:func:`~rhmpc.experiment.assembly.build_run`). With faults (``config.faults``),
    the document's ``faults`` holds one record per fault
    (:func:`rhmpc.experiment.faults.fault_report`).
    """
    built = time.perf_counter()
    run = build_run(config, implementation, _say if progress else None)
    built = time.perf_counter() - built
    loop = config.loop
    marks = fault_marks(run.faults, config.faults.after_s, loop.Ts, loop.duration)
    bar, callback = _progress_bar(config, run.label) if progress else (None, None)
    wall = time.perf_counter()
    try:
        result = run_closed_loop(
            run.plant, run.controller, run.truth, run.stream, config.loop, run.clock,
            anchor=run.anchor, robot=run.robot, progress=callback, trace_file=trace,
            yardstick=_gain_tick(run.controller) if gain_tick else None,
            marks=marks, points=run.points, measured=run.measured,
        )
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall
    doc = document(config, run, result, wall, implementation, gain_tick)
    doc["build_s"] = built
    return result, doc


def _say(text: str) -> None:
    """A progress line on stderr (what fitting a predictor before the run is doing)."""
    print(f"rhmpc: {text}", file=sys.stderr, flush=True)


def _progress_bar(config: RunConfig, label: str):
    """A tqdm bar on stderr and the loop's callback that moves it."""
    from tqdm import tqdm

    bar = tqdm(total=config.loop.ticks, unit="tick", unit_scale=True, leave=False,
               desc=f"{config.predictor} on {label}", mininterval=0.5)

    def callback(done: int) -> None:
        bar.update(done - bar.n)

    return bar, callback


def document(config: RunConfig, run: Run, result: LoopResult, wall: float,
             implementation: str, timed_gain: bool) -> dict[str, Any]:
    """The JSON document of a run (see :func:`run_experiment`)."""
    with warnings.catch_warnings():  # a metric with no finite tick is NaN, and said so by the CLI
        warnings.filterwarnings("ignore", "Mean of empty slice", RuntimeWarning)
        warnings.filterwarnings("ignore", "All-NaN slice encountered", RuntimeWarning)
        metrics = result.metrics()
    stats = result.controller_stats
    doc = {
        "schema": SCHEMA,
        "predictor": config.predictor,
        "scenario": run.label,
        "robot": config.robot,
        "seed": config.seed,
        "sensor": config.sensor,
        "ground_truth": config.ground_truth,
        "settling_s": config.loop.settling_s,
        **metrics,
        "fallbacks": int(stats.get("fallback_total", 0)),
        "controller": jsonable(stats),
        "implementation": implementation,
        "predictor_counts": jsonable(result.predictor_counts),
        "encoder": jsonable(run.controller.encoder_counts),
        "wall_s": wall,
        "real_time_factor": config.loop.duration / wall,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,  # Linux: KiB
        "settings": config.to_dict(),
        "versions": versions(),
    }
    predictor = getattr(run.reference, "predictor", None)
    if predictor is not None:  # its running RMS miss per lead (benchmarks/horizon_weights.py)
        errors = np.asarray(predictor.forecast_error_rms, dtype=float)
        doc["forecast_error_rms_mm"] = [None if not np.isfinite(v) else 1e3 * float(v)
                                        for v in errors]
        doc["forecast_lead_s"] = run.clock.dt
        doc["predictor_unit_m"] = getattr(predictor, "unit", None)  # metres per data unit
        if hasattr(predictor, "member_time"):  # a combination: each member against the period
            doc["member_time_us"] = predictor.member_time.summary()
    doc["predictor_clock"] = _clock_document(config, run)
    if config.predictor != "exact":
        counts, floor = result.predictor_counts, run.controller.gate_floor
        doc["outlier_gate"] = {
            "setting": config.reference.outlier_gate,
            "floor_mm": None if floor is None else 1e3 * floor,
            "calibration_s": 2 * config.reference.gate_calibration,  # convergence + calibration
            **{key: int(counts.get(key, 0))
               for key in ("outliers_rejected", "gate_unlocked", "retracted", "repaired")},
        }
    if run.faults:
        loop = config.loop
        doc["faults"] = jsonable(fault_report(config.faults.events, run.faults, result.segments,
                                              config.faults.after_s, loop.Ts, loop.duration))
    monitor = getattr(run.reference, "monitor", None)
    if monitor is not None:
        doc["heart_rate"] = monitor.summary()
    if timed_gain and np.isfinite(result.yardstick_us["p50"]):
        g = result.yardstick_us["p50"]
        doc["gain_tick_us"] = result.yardstick_us
        doc["tick_ratio_to_gain"] = {k: v / g for k, v in metrics["tick_us"].items()
                                     if k != "mean"}
        doc["tick_parts_ratio_to_gain"] = {
            part: {k: v / g for k, v in stats.items() if k != "mean"}
            for part, stats in metrics["tick_parts_us"].items()}
        doc["control_tick_ratio_to_gain"] = {k: v / g for k, v in
                                             metrics["control_tick_us"].items() if k != "mean"}
        # the tick's own work per simulated second (mean × rate): no simulator is faster
        doc["tick_per_simulated_s_g"] = metrics["tick_us"]["mean"] / config.loop.Ts / g
        # wall time per simulated second, in gain ticks: the simulation's own speed
        doc["wall_per_simulated_s_g"] = 1e6 * wall / config.loop.duration / g
    return doc


def _clock_document(config: RunConfig, run: Run) -> dict[str, Any]:
    """When the predictor ran, on what, and how old its newest sample was when it forecast."""
    clock = run.clock
    playback = None
    if clock.mode == "downsample" and config.sensor in ("sonomicrometry", "white", "recorded"):
        playback = config.sensor_settings.get("playback", DEFAULT_PLAYBACK)
    age = run.controller.mean_age
    return {
        "mode": clock.mode,
        "dt_s": clock.dt,
        "sensor_rate_hz": clock.sensor_rate,
        "playback": playback,
        "mean_sample_age_ms": None if not np.isfinite(age) else 1e3 * age,
        "description": clock.describe(playback),
    }


def _gain_tick(controller) -> GainTick | None:
    """``yardstick(x, r, u_prev)``: the gain tick of the controller's MPC (the C controller's:
    that of the Python MPC it was generated from), or None if it has none (a stand-in)."""
    try:
        return GainTick(controller.mpc)
    except AttributeError:
        return None


def jsonable(obj: Any) -> Any:
    """Plain JSON/TOML types: dicts with string keys, lists for tuples, Python numbers for
    numpy scalars and arrays (nested)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj
