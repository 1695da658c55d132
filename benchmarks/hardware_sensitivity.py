"""Sensitivity of Tuna et al.'s findings to the parameters no source gives.

``resonance`` and ``mismatch`` run ``--preset tuna2013-hardware`` with one setting changed at a
time (the cables' resonance; the controller's model, friction, stiction, delay, DAC, what the
error is scored from); ``noise`` runs ``--preset tuna2013`` with the sonomicrometer's white
range error scaled (a sensitivity of the cause, not a choice: the default is sized from §III-B).
Printed per variant and column: the exact reference's RMS error and effort and each RLS
predictor's RMS error over exact's, with the published table beside them. One process, in
sequence.

Usage::

    python benchmarks/hardware_sensitivity.py resonance [--duration 60] [--out FILE.json]
    python benchmarks/hardware_sensitivity.py mismatch  [--scenarios fixed-a2-top,...]
    python benchmarks/hardware_sensitivity.py noise
    python benchmarks/hardware_sensitivity.py stability   # cables: resonance × damping ratio

``stability`` runs the exact reference for 2 s per cell of resonance (40–150 Hz) × damping
ratio and prints the RMS error (mm; "unstable" above 5 mm, where the cable mode grows until the
DAC saturates).
"""

from __future__ import annotations

import argparse
import json
import sys

from rhmpc.cli.presets import PRESETS
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.studies.paper import TUNA2013

#: The preset each sweep changes, and the published table beside it.
PRESET = {"resonance": ("tuna2013-hardware", "II"), "mismatch": ("tuna2013-hardware", "II"),
          "noise": ("tuna2013", "I"), "stability": ("tuna2013-hardware", "II")}
#: Cable resonances [Hz] and damping ratios of the stability map.
RESONANCES = (40.0, 60.0, 80.0, 100.0, 150.0)
DAMPING_RATIOS = (0.05, 0.1, 0.2, 0.3, 0.5)
#: The default white range error [m] (sim.sensors.SonomicrometrySettings.range_noise).
_SIGMA = 88e-6

#: Variant name → the settings it changes on top of the sweep's preset.
SWEEPS: dict[str, dict[str, dict]] = {
    "resonance": {  # the cables where the loop is stable (``stability``: none in 40–150 Hz)
        "rigid": {},
        **{f"{f:g} Hz, zeta {z:g}": {"hardware.cable_resonance": f,
                                     "hardware.cable_damping_ratio": z, "hardware.substeps": 40}
           for f, z in ((300.0, 0.2), (500.0, 0.05), (500.0, 0.2))},
    },
    "mismatch": {
        "default (Cavusoglu model)": {},
        "controller = plant model": {"mismatch.parameters": None},
        "Cavusoglu, masses x0.8": {"mismatch.mass_scale": 0.8},
        "Cavusoglu, masses x1.2": {"mismatch.mass_scale": 1.2},
        "friction cancelled x0": {"mismatch.friction_scale": 0.0},
        "friction cancelled x0.7": {"mismatch.friction_scale": 0.7},
        "friction cancelled x1.3": {"mismatch.friction_scale": 1.3},
        "stiction x1.0": {"hardware.stiction_ratio": 1.0},
        "stiction x1.5": {"hardware.stiction_ratio": 1.5},
        "delay 0 ticks": {"hardware.delay_ticks": 0},
        "delay 2 ticks": {"hardware.delay_ticks": 2},
        "DAC 16 bits": {"hardware.dac_bits": 16},
        "DAC +-1.5 A": {"hardware.dac_range": 1.5},
        "error from the true tip": {"hardware.error_from": "true"},
        "ideal plant, tuna2013 weights": {"plant.model": "ideal", "mismatch.parameters": None},
    },
    "noise": {
        f"white {w:.2f} mm above 26 Hz": {"sensor_settings.range_noise": _SIGMA * w / 0.12}
        for w in (0.0, 0.06, 0.10, 0.12, 0.14, 0.22)
    },
}


def run_variant(preset: str, changes: dict, scenario: str, predictor: str, duration: float,
                seed: int) -> dict:
    """One closed-loop run of ``preset`` with ``changes``; its result document."""
    config = RunConfig(scenario=scenario, predictor=predictor, seed=seed).replace(
        **PRESETS[preset], **{"loop.duration": duration,
                              "loop.settling": min(20.0, duration / 3)})
    return run_experiment(config.replace(**changes))[1]


def table(rows: list[dict], scenarios: list[str], predictors: list[str], published: str) -> str:
    """Variant × column: exact RMS [mm] / effort [mN·m], and each RLS predictor's RMS ÷ exact."""
    paper = TUNA2013[(published, "rms_error_mm")]
    effort = TUNA2013[(published, "rms_effort_mNm")]
    out = [f"{'variant':<30}" + "".join(f"{s:>38}" for s in scenarios),
           f"{'Table ' + published:<30}" + "".join(
               f"{paper['exact'][s]:.3f} mm {effort['exact'][s]:5.1f} mN.m "
               f"g/e {paper['generalized'][s] / paper['exact'][s]:.2f} "
               f"o/e {paper['one-step'][s] / paper['exact'][s]:.2f}".rjust(38)
               for s in scenarios)]
    for variant in dict.fromkeys(r["variant"] for r in rows):
        cells = []
        for s in scenarios:
            got = {r["predictor"]: r for r in rows if r["variant"] == variant
                   and r["scenario"] == s}
            e = got.get("exact")
            cell = ("-" if e is None
                    else f"{e['rms_error_mm']:.3f} mm {e['rms_effort_mNm']:5.1f} mN.m")
            for p, tag in (("generalized", "g/e"), ("one-step", "o/e")):
                if p in predictors and p in got and e is not None:
                    cell += f" {tag} {got[p]['rms_error_mm'] / e['rms_error_mm']:.2f}"
            cells.append(cell.rjust(38))
        out.append(f"{variant:<30}" + "".join(cells))
    return "\n".join(out)


def stability(scenario: str, seed: int) -> str:
    """Resonance × damping ratio: the exact reference's RMS error over 2 s [mm]."""
    out = [f"{'f_r [Hz]':<10}" + "".join(f"{'zeta ' + format(z, 'g'):>12}"
                                         for z in DAMPING_RATIOS)]
    for f in RESONANCES:
        line = f"{f:<10g}"
        for z in DAMPING_RATIOS:
            doc = run_variant("tuna2013-hardware", {"hardware.cable_resonance": f,
                                                    "hardware.cable_damping_ratio": z},
                              scenario, "exact", 2.0, seed)
            rms = doc["rms_error_mm"]
            line += f"{'unstable' if rms > 5.0 else format(rms, '.3f'):>12}"
            print(f"{f:g} Hz zeta {z:g}: {rms:.3f} mm", file=sys.stderr, flush=True)
        out.append(line)
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sweep", choices=(*SWEEPS, "stability"))
    p.add_argument("--scenarios", default="fixed-a2-top,varying-a3-top")
    p.add_argument("--predictors", default="exact,generalized,one-step")
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--out", help="write every run's metrics as JSON")
    p.add_argument("--table", metavar="FILE.json", help="only print the table of a former --out")
    args = p.parse_args(argv)
    scenarios, predictors = args.scenarios.split(","), args.predictors.split(",")
    preset, published = PRESET[args.sweep]
    if args.sweep == "stability":
        print(stability(scenarios[0], args.seed))
        return 0
    if args.table:
        with open(args.table) as f:
            rows = json.load(f)
        print(table(rows, list(dict.fromkeys(r["scenario"] for r in rows)), predictors,
                    published))
        return 0
    rows = []
    for variant, changes in SWEEPS[args.sweep].items():
        for s in scenarios:
            for pred in predictors:
                doc = run_variant(preset, changes, s, pred, args.duration, args.seed)
                rows.append({"variant": variant, "scenario": s, "predictor": pred,
                             **{k: doc[k] for k in ("rms_error_mm", "max_error_mm",
                                                    "rms_effort_mNm", "fallbacks")}})
                print(f"{variant} {s} {pred}: {rows[-1]['rms_error_mm']:.4f} mm "
                      f"{rows[-1]['rms_effort_mNm']:.1f} mN.m", file=sys.stderr, flush=True)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    print(table(rows, scenarios, predictors, published))
    return 0


if __name__ == "__main__":
    sys.exit(main())
