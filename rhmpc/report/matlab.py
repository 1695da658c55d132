"""A closed-loop run for MATLAB users: one MAT file with the summary and the trace.

:func:`write_mat` writes (``scipy.io.savemat``, MATLAB 5 format, compressed) what ``load`` in
MATLAB or Octave reads as variables:

- ``summary``: the run's JSON document as a struct (numbers as doubles, ``null`` as ``[]``,
  lists as arrays or cells, names made valid MATLAB identifiers), and ``summary_json``, the
  document verbatim (``jsondecode(summary_json)`` gives it back);
- the trace, one row per traced tick, in SI units: ``time`` [s], ``tick``, ``ee``, ``poi``,
  ``reference0`` and ``error`` = ee − poi [m] (n × 3), ``error_norm`` [m], ``tau_mpc``,
  ``tau_command``, ``tau`` [N·m], ``q`` [rad], ``tick_ns`` [ns], and ``trace_stride``;
- where the run has them, the forecasts (``horizon_tick``, ``horizon_time`` [s], ``horizon``
  R × N × 3 [m]) and the measured samples (``sample_time`` [s], ``sample`` S × 3 [m]). On a
  recording these are its own samples, where the run is scored: ``sample`` is NaN where the
  score leaves a sample out (no measurement, or taken as an outlier by the controller),
  ``sample_recorded`` holds them as recorded and ``sample_scored`` says which are in the
  score; the trace keeps the ticks at their instants, so that the score is ``ee`` at
  ``sample_time`` against ``sample`` over the scored span;
- ``units``: each variable's unit, and ``description``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

#: The unit of each variable the file may hold.
UNITS = {
    "time": "s", "tick": "control tick (time = tick * Ts happens at (tick + 1) * Ts)",
    "ee": "m", "poi": "m", "reference0": "m", "error": "m", "error_norm": "m", "q": "rad",
    "tau_mpc": "N*m", "tau_command": "N*m", "tau": "N*m", "tick_ns": "ns",
    "horizon_tick": "control tick", "horizon_time": "s", "horizon": "m",
    "sample_time": "s", "sample": "m", "sample_recorded": "m", "sample_scored": "logical",
    "trace_stride": "ticks",
}
#: MATLAB's limit on a variable or field name.
NAME_MAX = 63


def write_mat(path: str | Path, result, doc: dict) -> Path:
    """Write a run's summary and trace as a MAT file (see the module docstring).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.mat`` file to write.
    result : rhmpc.sim.loop.LoopResult
        The run: its trace, ``settings.Ts`` and ``stride``; ``trace["q"]``, ``horizons`` and
        ``samples`` where present.
    doc : dict
        The run's JSON document (``rhmpc simulate --out``).

    Returns
    -------
    pathlib.Path
        The file written.
    """
    from scipy.io import savemat

    from rhmpc import io

    variables = {"summary": matlab_value(doc), "summary_json": json.dumps(doc, indent=1)}
    variables.update(trace_variables(result))
    variables["units"] = {k: v for k, v in UNITS.items() if k in variables}
    variables["description"] = (
        "rhmpc closed-loop run: one row per traced tick (every stride-th tick, then every "
        "tick of the run's last seconds); positions in the robot's workspace frame; "
        "summary holds the run's metrics in mm and mN*m as their names say")
    path = Path(path)
    with io.atomic_write(path) as f:
        savemat(f, variables, do_compression=True, oned_as="column", long_field_names=True)
    return path


def trace_variables(result) -> dict[str, np.ndarray]:
    """The trace, the forecasts and the samples as MAT variables (SI units)."""
    trace = getattr(result, "trace", None) or {}
    ee, poi = np.asarray(result.ee, float), np.asarray(result.poi, float)
    out = {"time": np.asarray(result.time, float), "ee": ee, "poi": poi,
           "reference0": np.asarray(result.reference0, float), "error": ee - poi,
           "error_norm": np.linalg.norm(ee - poi, axis=1),
           "tau_mpc": np.asarray(result.tau_mpc, float), "tau": np.asarray(result.tau, float)}
    for name in ("tick", "tau_command", "q", "tick_ns"):
        if name in trace:
            out[name] = np.asarray(trace[name], float)
    out["trace_stride"] = float(getattr(result, "stride", 1))
    horizons = getattr(result, "horizons", None)
    if horizons is not None and len(horizons[0]):
        ticks = np.asarray(horizons[0], float)
        out.update(horizon_tick=ticks, horizon_time=ticks * result.settings.Ts,
                   horizon=np.asarray(horizons[1], float))
    measured = getattr(result, "measured", ())
    samples = getattr(result, "samples", None)
    if len(measured):
        t, p, scored = measured
        left_out = ~np.isfinite(p).all(axis=1) | (~scored & _in_span(t, result))
        out.update(sample_time=np.asarray(t, float),
                   sample=np.where(left_out[:, None], np.nan, p),
                   sample_recorded=np.asarray(p, float), sample_scored=np.asarray(scored))
    elif samples is not None and len(samples[0]):
        out.update(sample_time=np.asarray(samples[0], float),
                   sample=np.asarray(samples[1], float))
    return out


def _in_span(t: np.ndarray, result) -> np.ndarray:
    """Whether each instant ``t`` [s] lies in the run's scored span [settling, duration)."""
    s = result.settings
    return (t >= s.settling_ticks * s.Ts - 1e-9) & (t < s.ticks * s.Ts - 1e-9)


def matlab_value(value):
    """A JSON value as ``savemat`` writes it for MATLAB: dicts as structs with valid field
    names, numbers as doubles, ``None`` as ``[]``, numeric lists as arrays, other lists as
    cells."""
    if isinstance(value, dict):
        return _struct(value)
    if value is None:
        return np.zeros((0, 0))
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | float | np.integer | np.floating):
        return float(value)
    if isinstance(value, str):
        return value
    if isinstance(value, list | tuple | np.ndarray):
        return _list(list(value) if not isinstance(value, np.ndarray) else value)
    return str(value)


def _list(items):
    """A numeric (nested) list as a double array, a list of booleans as a logical array,
    anything else as a cell array."""
    if isinstance(items, np.ndarray) and items.dtype.kind in "biuf":
        return items.astype(bool if items.dtype.kind == "b" else float)
    if len(items) and all(isinstance(v, bool | np.bool_) for v in items):
        return np.array(items, dtype=bool)
    try:
        array = np.array(items, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is not None and not any(isinstance(v, bool | None) for v in _flat(items)):
        return array
    cell = np.empty(len(items), dtype=object)
    for i, v in enumerate(items):
        cell[i] = matlab_value(v)
    return cell


def _flat(items):
    for v in items:
        if isinstance(v, list | tuple):
            yield from _flat(v)
        else:
            yield v


def _struct(d: dict) -> dict:
    """A dict with its keys made MATLAB field names (unique, ≤ 63 characters)."""
    out: dict = {}
    for key, value in d.items():
        name = field_name(str(key))
        base, n = name, 1
        while name in out:
            n += 1
            name = f"{base[: NAME_MAX - len(str(n)) - 1]}_{n}"
        out[name] = matlab_value(value)
    return out


def field_name(key: str) -> str:
    """A valid MATLAB identifier for ``key``: letters, digits and underscores, starting with a
    letter, at most 63 characters (``"p99.9"`` → ``"p99_9"``, ``"1st"`` → ``"x1st"``)."""
    name = re.sub(r"\W", "_", key, flags=re.ASCII) or "x"
    if not name[0].isalpha():
        name = "x" + name
    return name[:NAME_MAX]
