"""Sensitivity of Tuna et al.'s findings to the parameters no source gives.

``resonance`` and ``mismatch`` run ``--preset tuna2013-hardware`` with one setting changed at a
time (the cables' resonance; the controller's model, friction, stiction, delay, DAC, what the
error is scored from); ``noise`` runs ``--preset tuna2013`` with the sonomicrometer's white
range error scaled (a sensitivity of the cause, not a choice: the default is sized from §III-B).
Printed per variant and column: the exact reference's RMS error and effort and each RLS
predictor's RMS error over exact's, with the published table beside them. One process, in
sequence.

Usage::

    python benchmarks/hardware_sensitivity.py [all] [--quick]   # docs/results/tuna_sensitivity
    python benchmarks/hardware_sensitivity.py resonance [--duration 60] [--out FILE.json]
    python benchmarks/hardware_sensitivity.py mismatch  [--scenarios fixed-a2-top,...]
    python benchmarks/hardware_sensitivity.py noise
    python benchmarks/hardware_sensitivity.py stability   # cables: resonance × damping ratio

``stability`` runs the exact reference for 2 s per cell of resonance (40–150 Hz) × damping
ratio and prints the RMS error (mm; "unstable" above 5 mm, where the cable mode grows until the
DAC saturates). ``all`` (the default) runs ``mismatch``, ``noise``, ``resonance`` and
``stability`` and writes their tables to ``docs/results/tuna_sensitivity.{json,md}``;
``--quick`` runs 10 s on the first scenario and a 3 × 3 stability map.
"""

from __future__ import annotations

import argparse
import json
import sys

import _results as R

from rhmpc.cli.presets import PRESETS
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.presets import IDEAL_PLANT
from rhmpc.paper.tables import TUNA2013

#: The preset each sweep changes, and the published table beside it.
PRESET = {"resonance": ("tuna2013-hardware", "II"), "mismatch": ("tuna2013-hardware", "II"),
          "noise": ("tuna2013", "I"), "stability": ("tuna2013-hardware", "II")}
#: Cable resonances [Hz] and damping ratios of the stability map.
RESONANCES = (40.0, 60.0, 80.0, 100.0, 150.0)
DAMPING_RATIOS = (0.05, 0.1, 0.2, 0.3, 0.5)
#: Substeps per tick of the map's cables: h = 25 µs, the rotor alone on its friction within the
#: stability bound 2 J_r v_s / F_s (the preset's 4 are the rigid arm's).
CABLE_SUBSTEPS = 20
#: The default white range error [m] (rhmpc.sim.sensors.SonomicrometrySettings.range_noise).
_SIGMA = 88e-6
#: The exact reference's RMS error [mm] above which a stability cell is "unstable".
UNSTABLE_MM = 5.0
#: The sweeps of ``all``, in the order they run, with their captions.
CAPTIONS = {
    "mismatch": "Controller/plant mismatch, friction, stiction, delay, DAC, error source "
                "(hardware preset, beside Table II)",
    "noise": "White range error of the sonomicrometer (simulation preset, beside Table I)",
    "resonance": "Cable compliance where the loop is stable (hardware preset, beside Table II)",
}
SHORT = {"fixed-a2-top": "fixed a2", "varying-a3-top": "var. a3"}

#: Variant name → the settings it changes on top of the sweep's preset.
SWEEPS: dict[str, dict[str, dict]] = {
    "resonance": {  # the cables where the loop is stable (``stability``: none in 40–150 Hz)
        "rigid": {},
        **{f"{f:g} Hz, zeta {z:g}": {"plant.cable_resonance": f,
                                     "plant.cable_damping_ratio": z, "plant.substeps": 40}
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
        "stiction x1.0": {"plant.stiction_ratio": 1.0},
        "stiction x1.5": {"plant.stiction_ratio": 1.5},
        "delay 0 ticks": {"plant.delay_ticks": 0},
        "delay 2 ticks": {"plant.delay_ticks": 2},
        "DAC 16 bits": {"plant.dac_bits": 16},
        "DAC +-1.5 A": {"plant.dac_range": 1.5},
        "error from the true tip": {"plant.error_from": "true"},
        "ideal plant, tuna2013 weights": {**IDEAL_PLANT, "mismatch.parameters": None},
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


def stability_map(scenario: str, seed: int, resonances=RESONANCES,
                  ratios=DAMPING_RATIOS) -> list[dict]:
    """Resonance × damping ratio: the exact reference's RMS error over 2 s [mm].

    Parameters
    ----------
    scenario, seed
        The replica and the seed of every run.
    resonances, ratios
        The cables' resonances [Hz] and damping ratios of the map.

    Returns
    -------
    list of dict
        One ``{"resonance_hz", "damping_ratio", "rms_error_mm", "max_error_mm",
        "rms_effort_mNm"}`` per cell, row by row.
    """
    cells = []
    for f in resonances:
        for z in ratios:
            doc = run_variant("tuna2013-hardware", {"plant.cable_resonance": f,
                                                    "plant.cable_damping_ratio": z,
                                                    "plant.substeps": CABLE_SUBSTEPS},
                              scenario, "exact", 2.0, seed)
            cells.append({"resonance_hz": f, "damping_ratio": z,
                          **{k: doc[k] for k in ("rms_error_mm", "max_error_mm",
                                                 "rms_effort_mNm")}})
            print(f"{f:g} Hz zeta {z:g}: {doc['rms_error_mm']:.3f} mm", file=sys.stderr,
                  flush=True)
    return cells


def stability(cells: list[dict]) -> str:
    """The stability map as text: one line per resonance, one column per damping ratio."""
    ratios = list(dict.fromkeys(c["damping_ratio"] for c in cells))
    out = [f"{'f_r [Hz]':<10}" + "".join(f"{'zeta ' + format(z, 'g'):>12}" for z in ratios)]
    for f in dict.fromkeys(c["resonance_hz"] for c in cells):
        rms = [c["rms_error_mm"] for c in cells if c["resonance_hz"] == f]
        out.append(f"{f:<10g}" + "".join(
            f"{'unstable' if r > UNSTABLE_MM else format(r, '.3f'):>12}" for r in rms))
    return "\n".join(out)


def sweep(name: str, scenarios: list[str], predictors: list[str], duration: float,
          seed: int) -> list[dict]:
    """Every variant of sweep ``name`` × scenario × predictor: one row of metrics per run.

    Returns
    -------
    list of dict
        ``{"variant", "scenario", "predictor", "rms_error_mm", "max_error_mm",
        "rms_effort_mNm", "fallbacks"}`` per run, in the order run.
    """
    preset, rows = PRESET[name][0], []
    for variant, changes in SWEEPS[name].items():
        for s in scenarios:
            for pred in predictors:
                doc = run_variant(preset, changes, s, pred, duration, seed)
                rows.append({"variant": variant, "scenario": s, "predictor": pred,
                             **{k: doc[k] for k in ("rms_error_mm", "max_error_mm",
                                                    "rms_effort_mNm", "fallbacks")}})
                print(f"{name}: {variant} {s} {pred}: {rows[-1]['rms_error_mm']:.4f} mm "
                      f"{rows[-1]['rms_effort_mNm']:.1f} mN.m", file=sys.stderr, flush=True)
    return rows


def md_cells(exact: float, effort: float, gen: float | None, one: float | None) -> list[str]:
    """The four cells of one variant and column: exact RMS, effort, generalized ÷ and
    one-step ÷ exact (a dash where a predictor was not run)."""
    return [R.fmt(exact, 3), R.fmt(effort, 1),
            *(R.fmt(None if r is None else r / exact, 2) for r in (gen, one))]


def md_table(rows: list[dict], scenarios: list[str], published: str) -> str:
    """A sweep as Markdown: the published table's row, then variant × column.

    Parameters
    ----------
    rows
        The rows of :func:`sweep`.
    scenarios
        The columns run, in order.
    published
        The table beside them: ``"I"`` or ``"II"``.
    """
    paper = TUNA2013[(published, "rms_error_mm")]
    effort = TUNA2013[(published, "rms_effort_mNm")]
    out = [[f"Table {published} (paper)" if i == 0 else "", SHORT.get(s, s),
            *md_cells(paper["exact"][s], effort["exact"][s], paper["generalized"][s],
                      paper["one-step"][s])] for i, s in enumerate(scenarios)]
    for variant in dict.fromkeys(r["variant"] for r in rows):
        for i, s in enumerate(scenarios):
            got = {r["predictor"]: r for r in rows
                   if r["variant"] == variant and r["scenario"] == s}
            rms = {p: got[p]["rms_error_mm"] if p in got else None
                   for p in ("generalized", "one-step")}
            out.append([variant if i == 0 else "", SHORT.get(s, s),
                        *md_cells(got["exact"]["rms_error_mm"], got["exact"]["rms_effort_mNm"],
                                  rms["generalized"], rms["one-step"])])
    header = ["variant", "column", "exact RMS [mm]", "exact effort [mN·m]",
              "generalized ÷ exact", "one-step ÷ exact"]
    return R.table(header, out)


def md_stability(cells: list[dict]) -> str:
    """The stability map as Markdown: resonance × damping ratio, "unstable" above 5 mm,
    else the RMS error [mm] and, in parentheses, the RMS effort [mN·m]."""
    ratios = list(dict.fromkeys(c["damping_ratio"] for c in cells))
    rows = []
    for f in dict.fromkeys(c["resonance_hz"] for c in cells):
        row = [c for c in cells if c["resonance_hz"] == f]
        rows.append([R.fmt(f, 0), *(
            "unstable" if c["rms_error_mm"] > UNSTABLE_MM
            else f"{R.fmt(c['rms_error_mm'], 3)} ({R.fmt(c['rms_effort_mNm'], 0)})"
            for c in row)])
    return R.table(["resonance [Hz]", *[f"ζ = {R.fmt(z, 2)}" for z in ratios]], rows)


def write_all(scenarios: list[str], predictors: list[str], duration: float, seed: int,
              quick: bool) -> None:
    """Run every sweep and the stability map; write ``docs/results/tuna_sensitivity``."""
    data = {"duration_s": duration, "seed": seed, "scenarios": scenarios,
            "predictors": predictors, "unstable_above_mm": UNSTABLE_MM, "sweeps": {}}
    tables = {}
    for name, caption in CAPTIONS.items():
        rows = sweep(name, scenarios, predictors, duration, seed)
        data["sweeps"][name] = rows
        tables[f"{name}|{caption}"] = md_table(rows, scenarios, PRESET[name][1])
    grid = (RESONANCES[::2], DAMPING_RATIOS[::2]) if quick else (RESONANCES, DAMPING_RATIOS)
    data["stability"] = stability_map(scenarios[0], seed, *grid)
    tables["stability|Cable stability (hardware preset, exact reference, "
           f"{SHORT.get(scenarios[0], scenarios[0])}, 2-s runs): RMS error [mm] (RMS effort "
           f"[mN·m]), \"unstable\" above {UNSTABLE_MM:g} mm"] = \
        md_stability(data["stability"])
    R.write("tuna_sensitivity", "Sensitivity of Tuna et al. 2013's findings", data, tables,
            quick, notes="Each variant changes one setting of the preset; the ratios are each "
                         "RLS predictor's RMS error over the exact reference's in the same "
                         "variant and column. \"Unstable\": the cable mode grows until the "
                         "DAC saturates.")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sweep", nargs="?", default="all", choices=("all", *SWEEPS, "stability"))
    p.add_argument("--scenarios", default="fixed-a2-top,varying-a3-top")
    p.add_argument("--predictors", default="exact,generalized,one-step")
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--quick", action="store_true", help="10-s runs on the first scenario")
    p.add_argument("--out", help="write every run's metrics as JSON")
    p.add_argument("--table", metavar="FILE.json", help="only print the table of a former --out")
    args = p.parse_args(argv)
    scenarios, predictors = args.scenarios.split(","), args.predictors.split(",")
    duration = 10.0 if args.quick else args.duration
    scenarios = scenarios[:1] if args.quick else scenarios
    if args.sweep == "all":
        write_all(scenarios, predictors, duration, args.seed, args.quick)
        return 0
    if args.sweep == "stability":
        print(stability(stability_map(scenarios[0], args.seed)))
        return 0
    published = PRESET[args.sweep][1]
    if args.table:
        with open(args.table) as f:
            rows = json.load(f)
        print(table(rows, list(dict.fromkeys(r["scenario"] for r in rows)), predictors,
                    published))
        return 0
    rows = sweep(args.sweep, scenarios, predictors, duration, args.seed)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)
    print(table(rows, scenarios, predictors, published))
    return 0


if __name__ == "__main__":
    sys.exit(main())
