"""Every bad input gets one clear line and exit code 2, or a stated safe action with a warning.

One table across the commands: the arguments, the files they read, the exit code and a regular
expression that the first line of stderr must match (tqdm's progress and argparse's usage block
left aside; ``None``: nothing on stderr). Each case runs in-process through
:func:`rhmpc.cli.main`. No case may print a traceback or let an exception out; a refusal
(exit 2) is exactly one ``error:`` line, the last, after at most a few one-line warnings.
The cases that run a closed loop are marked slow; the others fail before any simulation.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from rhmpc.cli import main
from tests.sim.recordings.bags import POSE_STAMPED, STRING, messages, write_bag

#: A file to create: text, bytes, ``None`` for a directory, or a function that writes it.
Content = str | bytes | None | Callable[[Path], None]

T = np.arange(0.0, 6.0, 1 / 25.0)
#: 5 mm of heart-like motion [mm]: a 1.2 Hz heart and 0.25 Hz breathing, sampled at 25 Hz.
HEART_MM = np.column_stack([2.5 * np.sin(2 * np.pi * 1.2 * T),
                            1.5 * np.sin(2 * np.pi * 1.2 * T + 1),
                            2.0 * np.sin(2 * np.pi * 0.25 * T)])


def csv(t: np.ndarray = T, z: np.ndarray = HEART_MM) -> str:
    """A CSV recording ``t,x,y,z`` [s, mm]; NaN is written as an empty field (a dropout)."""
    def field(v: float) -> str:
        return "" if math.isnan(v) else f"{v:.6g}"

    rows = (",".join(map(field, (ti, *zi))) for ti, zi in zip(t, z, strict=True))
    return "t,x,y,z\n" + "\n".join(rows) + "\n"


def with_samples(rows: slice | int, value: float) -> np.ndarray:
    z = HEART_MM.copy()
    z[rows] = value
    return z


def complex_npz(path: Path) -> None:
    np.savez(path, t=T, position=(HEART_MM / 1000).astype(complex) + 1j, units="m")


def mat(time_scale: float, **extra: str) -> Callable[[Path], None]:
    """A MAT file: ``X`` 3 × n [mm], ``t`` = ``time_scale`` × seconds, ``units`` and ``extra``."""
    def write(path: Path) -> None:
        scipy.io.savemat(path, {"X": HEART_MM.T, "t": T * time_scale, "units": "mm", **extra})

    return write


def fifo(path: Path) -> None:
    os.mkfifo(path)


def bag(path: Path) -> None:
    """A rosbag2 folder (MCAP) of a POI and a distracting topic, 6 s at 25 Hz [m]."""
    stamps = 1_700_000_000 * 10**9 + np.rint(T * 1e9).astype(np.int64)
    rows = messages(stamps, stamps + 5_000_000, HEART_MM[:, None] / 1000)
    write_bag(path, "mcap", {"/tracker/poi": (POSE_STAMPED, rows),
                             "/camera/info": (STRING, rows[::10])})


#: A rosbag2 folder's metadata naming one MCAP file.
BAG_METADATA = ("rosbag2_bagfile_information:\n  relative_file_paths: [b.mcap]\n"
                "  storage_identifier: mcap\n")


def link(target: str) -> Callable[[Path], None]:
    """A symbolic link to ``target`` (relative to the link's folder)."""
    def write(path: Path) -> None:
        path.symlink_to(target)

    return write


def read_only_dir(path: Path) -> None:
    path.mkdir()
    path.chmod(0o555)
    try:
        (path / "probe").touch()
    except PermissionError:
        return
    pytest.skip("permissions do not restrict this user (root): a read-only folder is writable")


def spec(scenario: str = "fixed-a2-top", predictor: str = "one-step") -> str:
    """A one-point ``rhmpc tune`` specification."""
    return (f'name = "bad"\n[base]\npredictor = "{predictor}"\n[base.loop]\nduration = 0.5\n'
            '[parameters]\n"mpc.effort_weight" = [1e-4]\n'
            f'[evaluate]\nscenarios = ["{scenario}"]\nseeds = [0]\n'
            '[objective]\nmetric = "rms_error_mm"\n')


def slow(*case, xfail: str | None = None):
    """A case that runs a closed loop; ``xfail``: a known defect, the reason."""
    marks = [pytest.mark.slow]
    if xfail:
        marks.append(pytest.mark.xfail(strict=True, reason=xfail))
    return pytest.param(*case[1:], id=case[0], marks=marks)


SIM = ["simulate", "--duration", "1"]
DATA_SIM = ["simulate", "--duration", "1", "--data"]
VALID_PREDICTORS = r"; valid: one-step, generalized, ekf"
VALID_SCENARIOS = r"; valid( names)?: fixed-a2-top, fixed-a1-top"

#: (id, argv, files in the working directory, exit code, regex of stderr's first line or None)
CASES = [
    # rhmpc data: recordings that cannot be read, absurd requests
    ("data-corrupt-npz", ["data", "show", "fake.npz"], {"fake.npz": b"PK\x03\x04" + bytes(200)},
     2, r"rhmpc data: error: fake\.npz: not a readable \.npz archive \(File is not a zip file\)$"),
    ("data-huge-field", ["data", "show", "big.csv"],
     {"big.csv": "t,x,y,z\n0," + "1" * 140_000 + ",0,0\n"},
     2, r"rhmpc data: error: big\.csv, line 2: a field longer than 131072 characters"),
    ("data-text-row", ["data", "show", "text.csv"],
     {"text.csv": "t,x,y,z\n0,1,2,3\n0.04,oops,2,3\n0.08,1,2,3\n"},
     2, r"rhmpc data: error: text\.csv, line 3: column x: 'oops' is not a number$"),
    ("data-binary", ["data", "show", "bin.csv"], {"bin.csv": bytes(range(256)) * 4},
     2, r"rhmpc data: error: bin\.csv: not a text file"),
    ("data-bad-header", ["data", "show", "h.csv"], {"h.csv": "a,b,c\n1,2,3\n"},
     2, r"rhmpc data: error: h\.csv, line 1: header columns a,b,c are not t,x,y,z"),
    ("data-infinite", ["data", "show", "i.csv"], {"i.csv": "t,x,y,z\n0,1,2,3\n0.1,inf,2,3\n"},
     2, r"rhmpc data: error: i\.csv, line 3: column x: 'inf' is not finite \(leave the field "
        r"empty for a missing sample\)$"),
    ("data-one-sample", ["data", "show", "o.csv"], {"o.csv": "t,x,y,z\n0,1,2,3\n"},
     2, r"rhmpc data: error: o\.csv: needs at least two samples, found 1$"),
    ("data-empty-file", ["data", "show", "empty.csv"], {"empty.csv": ""},
     2, r"rhmpc data: error: empty\.csv: empty file: no header and no samples$"),
    ("data-missing-file", ["data", "show", "nope.csv"], {},
     2, r"rhmpc data: error: nope\.csv: no such file$"),
    ("data-directory", ["data", "show", "dir.csv"], {"dir.csv": None},
     2, r"rhmpc data: error: dir\.csv: a folder, not a regular file; give a file$"),
    ("data-garbage-bag", ["data", "show", "g.bag"], {"g.bag": b"#ROSBAG V2.0\n" + bytes(300)},
     2, r"rhmpc data: error: g\.bag: not a readable ROS bag \("),
    ("data-bag-fifo", ["data", "show", "b"],
     {"b": None, "b/metadata.yaml": BAG_METADATA, "b/b.mcap": fifo},
     2, r"rhmpc data: error: b/b\.mcap: a named pipe \(FIFO\), not a regular file"),
    ("sim-bag-no-topic", [*DATA_SIM, "rec", "--topic", "/nope"], {"rec": bag},
     2, r"rhmpc simulate: error: rec: no topic /nope; the bag holds /camera/info "
        r"\(std_msgs/String, 15\), /tracker/poi \(geometry_msgs/PoseStamped, 150\)$"),
    ("sim-bag-wrong-type", [*DATA_SIM, "rec", "--topic", "/camera/info"], {"rec": bag},
     2, r"rhmpc simulate: error: rec: topic /camera/info is std_msgs/String, which is not read"),
    ("data-garbage-mat", ["data", "show", "g.mat"], {"g.mat": b"MATLAB 5.0" + bytes(300)},
     2, r"rhmpc data: error: g\.mat: not a readable MATLAB file"),
    ("data-mat-times-in-us-unlabelled", ["data", "show", "us.mat"], {"us.mat": mat(1e6)},
     2, r"rhmpc data: error: us\.mat: one sample every 4e\+04 s \(2\.5e-05 Hz\) cannot follow a "
        r"heartbeat .*if the times are in microseconds, say so"),
    ("data-mm-as-m", ["data", "show", "mm.csv", "--units", "m"], {"mm.csv": csv()},
     0, r"rhmpc data: warning: mm\.csv: the motion spans 4993 mm peak to peak, read in m as "
        r"--units says; .* pass --units mm$"),
    ("data-export-absurd-duration", ["data", "export", "fixed-a2-top", "big.csv",
                                     "--duration", "1e12"], {},
     2, r"rhmpc data: error: 1e\+12 s of fixed-a2-top at 257 Hz is 2\.57e\+14 samples: export "
        r"would need about .* \(lower --duration or --rate\)$"),
    ("data-export-over-file", ["data", "export", "fixed-a2-top", "e.csv", "--duration", "1"],
     {"e.csv": "mine\n"}, 2, r"rhmpc data: error: e\.csv exists; pass --force to overwrite$"),
    ("data-export-extension", ["data", "export", "fixed-a2-top", "e.txt", "--duration", "1"], {},
     2, r"rhmpc data: error: e\.txt: output must end in \.csv or \.npz$"),
    ("data-bpm", ["data", "show", "fixed-a2-top", "--bpm", "1e6"], {},
     2, r"rhmpc data: error: --bpm must be within 20–250 beats/min, got 1e\+06$"),
    ("data-duration-negative", ["data", "show", "fixed-a2-top", "--duration", "-1"], {},
     2, r"rhmpc data: error: --duration must be positive, got -1$"),
    ("data-seed-fraction", ["data", "show", "fixed-a2-top", "--seed", "1.5"], {},
     2, r"rhmpc data show: error: argument --seed: invalid int value: '1\.5'$"),
    ("data-unknown-record", ["data", "show", "fixed-a2-top", "--record", "nosuch"], {},
     2, r"rhmpc data: error: nosuch: no annotation file nosuch\.atr"),
    # rhmpc simulate: settings
    ("sim-seed-fraction", [*SIM, "--set", "seed=1.5"], {},
     2, r"rhmpc simulate: error: seed must be an integer, got 1\.5$"),
    ("sim-seed-huge", [*SIM, "--set", "seed=1e30"], {},
     2, r"rhmpc simulate: error: seed must be an integer, got 1e\+30$"),
    ("sim-seed-negative", [*SIM, "--seed", "-1"], {},
     2, r"rhmpc simulate: error: seed must be an integer in 0 … 2⁶³ − 1, got -1$"),
    ("sim-robot-list", [*SIM, "--set", "robot=[1]"], {},
     2, r"rhmpc simulate: error: robot must be a name \(a string\), got \[1\]$"),
    ("sim-order-huge", [*SIM, "--set", "predictor_settings.order=100000"], {},
     2, r"rhmpc simulate: error: a regressor of 300000 values .* needs 671 GiB for the RLS's "
        r"covariance; at most 8192 values fit in 512 MiB: lower the order$"),
    ("sim-ts-1", [*SIM, "--set", "loop.Ts=1"], {},
     2, r"rhmpc simulate: error: \[loop\] Ts must be between 0\.0001 and 0\.01 s, got 1$"),
    ("sim-ts-tiny", [*SIM, "--set", "loop.Ts=1e-9"], {},
     2, r"rhmpc simulate: error: \[loop\] Ts must be between 0\.0001 and 0\.01 s, got 1e-09$"),
    ("sim-downsample-huge", [*SIM, "--set", "loop.downsample=100000"], {},
     2, r"rhmpc simulate: error: \[loop\] downsample must be an integer in 1 … 1000 \[ticks\], "
        r"got 100000$"),
    ("sim-duration-huge", ["simulate", "--duration", "1e6"], {},
     2, r"rhmpc simulate: error: \[loop\] duration must be > 0 and at most 86400 s, "
        r"got 1000000\.0$"),
    ("sim-duration-negative", ["simulate", "--duration", "-1"], {},
     2, r"rhmpc simulate: error: \[loop\] duration must be > 0 and at most 86400 s, got -1\.0$"),
    ("sim-duration-nan", ["simulate", "--duration", "nan"], {},
     2, r"rhmpc simulate: error: \[loop\] duration must be > 0 and at most 86400 s, got nan$"),
    ("sim-settling-too-long", [*SIM, "--settling", "5"], {},
     2, r"rhmpc simulate: error: \[loop\] settling must be in \[0, duration\) \[s\], got 5\.0 "
        r"with duration 1\.0$"),
    ("sim-unknown-section", [*SIM, "--set", "nosuch.key=1"], {},
     2, r"rhmpc simulate: error: unknown section 'nosuch' in nosuch\.key; valid sections: loop,"),
    ("sim-set-without-value", [*SIM, "--set", "mpc.horizon"], {},
     2, r"rhmpc simulate: error: --set 'mpc\.horizon': expected SECTION\.KEY=VALUE$"),
    ("sim-horizon-0", [*SIM, "--set", "mpc.horizon=0"], {},
     2, r"rhmpc simulate: error: \[mpc\] horizon must be an integer >= 1, got 0$"),
    ("sim-horizon-text", [*SIM, "--set", "mpc.horizon=abc"], {},
     2, r"rhmpc simulate: error: \[mpc\] horizon must be an integer >= 1, got 'abc'$"),
    ("sim-effort-nan", [*SIM, "--set", "mpc.effort_weight=nan"], {},
     2, r"rhmpc simulate: error: \[mpc\] effort_weight must be a finite number, got nan$"),
    ("sim-effort-negative", [*SIM, "--set", "mpc.effort_weight=-1"], {},
     2, r"rhmpc simulate: error: \[mpc\] effort_weight must be >= 0, got -1$"),
    ("sim-unknown-predictor", [*SIM, "--predictor", "nosuch"], {},
     2, r"rhmpc simulate: error: unknown predictor 'nosuch'" + VALID_PREDICTORS),
    ("sim-unknown-robot", [*SIM, "--robot", "nosuch"], {},
     2, r"rhmpc simulate: error: unknown robot 'nosuch'; valid robots: phantom,"),
    ("sim-unknown-sensor", [*SIM, "--sensor", "nosuch"], {},
     2, r"rhmpc simulate: error: sensor 'nosuch': unknown sensor 'nosuch'; valid names: "),
    ("sim-unknown-scenario", [*SIM, "--scenario", "nosuch"], {},
     2, r"rhmpc simulate: error: unknown scenario 'nosuch'" + VALID_SCENARIOS),
    ("sim-unknown-rr", [*SIM, "--rr", "nosuch"], {},
     2, r"rhmpc simulate: error: nosuch: no annotation file nosuch\.atr"),
    ("sim-host-stalls-negative", [*SIM, "--host-stalls", "-1"], {},
     2, r"rhmpc simulate: error: --host-stalls must be between 0 and 600 s, got -1$"),
    ("sim-broken-toml", [*SIM, "--config", "run.toml"], {"run.toml": "[mpc\nhorizon = 5\n"},
     2, r"rhmpc simulate: error: run\.toml: not valid TOML: Expected '\]' at the end of a table "
        r"declaration \(at line 1, column 5\)$"),
    ("sim-missing-config", [*SIM, "--config", "nope.toml"], {},
     2, r"rhmpc simulate: error: nope\.toml: no such file$"),
    # rhmpc simulate --data
    ("sim-data-complex", [*DATA_SIM, "c.npz"], {"c.npz": complex_npz},
     2, r"rhmpc simulate: error: c\.npz: 'position' holds complex numbers; positions and times "
        r"must be real"),
    slow("sim-data-spike", [*DATA_SIM, "spike.csv", "--json"],
         {"spike.csv": csv(z=with_samples(np.s_[15, 0], 1e300))},
         0, r"rhmpc simulate: warning: spike\.csv: 1 sample\(s\) lie more than 10 × the motion's "
            r"span \(.*\) from the rest, the farthest 1e\+300 mm away \(sample 16, t = 0\.6 s\)"),
    slow("sim-data-mostly-nan", [*DATA_SIM, "nan.csv"],
         {"nan.csv": csv(z=with_samples(np.s_[3:], math.nan))},
         2, r"rhmpc simulate: warning: nan\.csv: 98\.0 % of the samples are missing \(3 of 150 "
            r"complete"),
    slow("sim-data-mat-us", [*DATA_SIM, "us.mat"], {"us.mat": mat(1e6, time_units="us")},
         0, None),
    ("sim-data-mat-us-unlabelled", [*DATA_SIM, "us.mat"], {"us.mat": mat(1e6)},
     2, r"rhmpc simulate: error: us\.mat: one sample every 4e\+04 s \(2\.5e-05 Hz\) cannot "
        r"follow a heartbeat"),
    ("sim-data-csv-ms-unlabelled", [*DATA_SIM, "ms.csv"], {"ms.csv": csv(t=T * 1e3)},
     2, r"rhmpc simulate: error: ms\.csv: one sample every 40 s \(0\.025 Hz\) cannot follow a "
        r"heartbeat .*if the times are in milliseconds, say so \(a CSV header t_ms"),
    slow("sim-data-mm-as-m", [*DATA_SIM, "mm.csv", "--units", "m"], {"mm.csv": csv()},
         0, r"rhmpc simulate: warning: mm\.csv: the motion spans 4993 mm peak to peak, read in "
            r"m as --units says; .* pass --units mm$"),
    ("sim-data-time-back", [*DATA_SIM, "back.csv"],
     {"back.csv": csv(t=np.r_[T[:50], T[40], T[51:]])},
     2, r"rhmpc simulate: error: back\.csv, line 52: time 1\.6 is not after the previous time "
        r"1\.96 \(times must increase strictly\)$"),
    ("sim-data-time-repeated", [*DATA_SIM, "rep.csv"],
     {"rep.csv": csv(t=np.r_[T[:50], T[49], T[51:]])},
     2, r"rhmpc simulate: error: rep\.csv, line 52: time 1\.96 is not after the previous time "
        r"1\.96 \(times must increase strictly\)$"),
    ("sim-data-too-short", [*DATA_SIM, "mm.csv", "--duration", "60"], {"mm.csv": csv()},
     2, r"rhmpc simulate: error: mm\.csv: the recording lasts 6\.00 s, the run asks for 60\.00 s "
        r"\(set --duration\)$"),
    ("sim-data-and-scenario", ["simulate", "--data", "mm.csv", "--scenario", "fixed-a2-top"],
     {"mm.csv": csv()},
     2, r"rhmpc simulate: error: argument --scenario: not allowed with argument --data$"),
    # rhmpc simulate: outputs, checked before the run
    ("sim-out-missing-dir", [*SIM, "--out", "no/such/run.json"], {},
     2, r"rhmpc simulate: error: --out no/such/run\.json: no such directory .*/no/such$"),
    ("sim-plot-read-only", [*SIM, "--plot", "ro/run.png"], {"ro": read_only_dir},
     2, r"rhmpc simulate: error: --plot ro/run\.png: cannot write there$"),
    ("sim-plot-under-a-file", [*SIM, "--plot", "f/run.png"], {"f": "a file\n"},
     2, r"rhmpc simulate: error: --plot f/run\.png: no such directory .*/f$"),
    ("sim-view-extension", [*SIM, "--view", "run.png"], {},
     2, r"rhmpc simulate: error: --view run\.png: the file must end in \.html$"),
    ("sim-trace-missing-dir", [*SIM, "--trace", "no/t.npz"], {},
     2, r"rhmpc simulate: error: --trace no/t\.npz: no such directory .*/no$"),
    slow("sim-plot-default-settling", [*SIM, "--plot", "run.png"], {}, 0, None),
    # rhmpc export
    ("export-over-users-file", ["export", "out"], {"out": None, "out/notes.txt": "mine\n"},
     2, r"rhmpc export: error: out is not empty: give --force to replace the files that rhmpc "
        r"export writes \(nothing else is touched\), or choose an empty directory$"),
    ("export-into-a-file", ["export", "f"], {"f": "a file\n"},
     2, r"rhmpc export: error: f: exists and is not a directory$"),
    ("export-ekf", ["export", "out", "--predictor", "ekf"], {},
     2, r"rhmpc export: error: argument --predictor: invalid choice: 'ekf' \(choose from "
        r"'one-step', 'generalized'\)$"),
    ("export-rate-0", ["export", "out", "--rate", "0"], {},
     2, r"rhmpc export: error: the sensor's rate must be > 0 Hz, got 0\.0$"),
    ("export-rate-nan", ["export", "out", "--rate", "nan"], {},
     2, r"rhmpc export: error: the sensor's rate must be > 0 Hz, got nan$"),
    # rhmpc tune, compare, bench, config
    ("tune-unknown-scenario", ["tune", "s.toml", "--dry-run"], {"s.toml": spec("nosuch")},
     2, r"rhmpc tune: error: s\.toml: evaluate\.scenarios: unknown scenario 'nosuch'"
        + VALID_SCENARIOS),
    ("tune-unknown-predictor", ["tune", "s.toml", "--dry-run"],
     {"s.toml": spec(predictor="nosuch")},
     2, r"rhmpc tune: error: s\.toml: parameters \(mpc\.effort_weight = 0\.0001\): unknown "
        r"predictor 'nosuch'" + VALID_PREDICTORS),
    ("tune-missing-spec", ["tune", "nope.toml"], {},
     2, r"rhmpc tune: error: nope\.toml: no such file$"),
    ("tune-broken-spec", ["tune", "s.toml"], {"s.toml": "name = \n"},
     2, r"rhmpc tune: error: s\.toml: not valid TOML: Invalid value \(at line 1, column 8\)$"),
    ("tune-report-missing", ["tune", "report", "nope.jsonl"], {},
     2, r"rhmpc tune: error: nope\.jsonl: no such file$"),
    ("compare-unknown-scenario", ["compare", "--scenarios", "nosuch", "--duration", "1"], {},
     2, r"rhmpc compare: error: unknown scenario\(s\) nosuch" + VALID_SCENARIOS),
    ("compare-unknown-predictor", ["compare", "--predictors", "nosuch", "--duration", "1"], {},
     2, r"rhmpc compare: error: unknown predictor\(s\) nosuch" + VALID_PREDICTORS),
    ("compare-seeds-0", ["compare", "--seeds", "0", "--duration", "1"], {},
     2, r"rhmpc compare: error: --seeds and --jobs must be >= 1$"),
    ("compare-jobs-0", ["compare", "--jobs", "0", "--duration", "1"], {},
     2, r"rhmpc compare: error: --seeds and --jobs must be >= 1$"),
    ("compare-duration-nan", ["compare", "--duration", "nan", "--predictors", "hold"], {},
     2, r"rhmpc compare: error: \[loop\] duration must be > 0 and at most 86400 s, got nan$"),
    ("bench-negative-jump", ["bench", "--jump-mm", "-1", "--ticks", "100"], {},
     2, r"rhmpc bench: error: --jump-mm and --jump-every must be >= 0$"),
    ("bench-ticks-0", ["bench", "--ticks", "0"], {},
     2, r"rhmpc bench: error: --ticks must be >= 1, got 0$"),
    ("config-unknown-preset", ["config", "show", "--preset", "nosuch"], {},
     2, r"rhmpc config show: error: argument --preset: invalid choice: 'nosuch' \(choose from "
        r"'tuna2013', 'hardware', 'tuna2013-hardware'\)$"),
    ("config-unknown-setting", ["config", "show", "--set", "mpc.nosuch=1"], {},
     2, r"rhmpc config: error: unknown setting\(s\) mpc\.nosuch; valid keys of \[mpc\]: horizon,"),
    ("config-missing-file", ["config", "show", "--config", "nope.toml"], {},
     2, r"rhmpc config: error: nope\.toml: no such file$"),
    ("config-wrong-type", ["config", "show", "--config", "r.toml"],
     {"r.toml": '[mpc]\nhorizon = "ten"\n'},
     2, r"rhmpc config: error: r\.toml: \[mpc\] horizon must be an integer >= 1, got 'ten'$"),
    ("config-misspelt-key", ["config", "show", "--config", "r.toml"],
     {"r.toml": "[mpc]\nhorizn = 10\n"},
     2, r"rhmpc config: error: r\.toml: \[mpc\] unknown MPCSettings setting\(s\): horizn; "
        r"valid: horizon,"),
    # files in through one reader, out through one writer; bounds from one table
    ("config-fifo", ["config", "show", "--config", "fifo.toml"], {"fifo.toml": fifo},
     2, r"rhmpc config: error: fifo\.toml: a named pipe \(FIFO\), not a regular file"),
    ("config-dev-zero", ["config", "show", "--config", "/dev/zero"], {},
     2, r"rhmpc config: error: /dev/zero: a character device, not a regular file; give a file$"),
    ("tune-dev-zero", ["tune", "/dev/zero"], {},
     2, r"rhmpc tune: error: /dev/zero: a character device, not a regular file; give a file$"),
    ("sim-toml-5000-deep", [*SIM, "--config", "deep.toml"],
     {"deep.toml": "a = " + "[" * 5000 + "]" * 5000 + "\n"},
     2, r"rhmpc simulate: error: deep\.toml: nested 5000 levels deep; at most 64 are read$"),
    ("tune-report-bad-line", ["tune", "report", "r.jsonl"],
     {"r.jsonl": '{"key": "zzz", "status": "ok"}\n'},
     2, r"rhmpc tune: error: r\.jsonl: no results yet \(skipped 1 line\(s\) that are not "
        r"results records \(the first: line 1\)"),
    ("tune-dry-run-bad-line", ["tune", "s.toml", "--dry-run", "--results", "r.jsonl"],
     {"s.toml": spec(), "r.jsonl": '{"key": "zzz", "status": "ok"}\n'},
     0, r"rhmpc tune: warning: r\.jsonl: skipped 1 line\(s\) that are not results records"),
    ("sim-model-empty", [*SIM, "--predictor", "ridge", "--set",
                         'predictor_settings.model="empty.npz"'], {"empty.npz": b""},
     2, r"rhmpc simulate: error: empty\.npz: an empty file \(0 bytes\), not a saved model$"),
    ("sim-model-missing", [*SIM, "--predictor", "ridge", "--set",
                           'predictor_settings.model="none.npz"'], {},
     2, r"rhmpc simulate: error: none\.npz: no such file$"),
    ("sim-out-is-input", [*DATA_SIM, "rec.mat", "--out", "./rec.mat"], {"rec.mat": mat(1.0)},
     2, r"rhmpc simulate: error: --out rec\.mat: is an input of this run \(rec\.mat\)"),
    ("sim-trace-through-link", [*SIM, "--trace", "t.npz"], {"t.npz": link("victim.npz")},
     2, r"rhmpc simulate: error: --trace t\.npz: a symbolic link \(to victim\.npz\)"),
    ("export-through-link", ["export", "out", "--force"],
     {"out": None, "victim.h": "keep\n", "out/rhmpc.h": link("../victim.h")},
     2, r"rhmpc export: error: out/rhmpc\.h: a symbolic link \(to \.\./victim\.h\)"),
    ("data-csv-ms-1khz", ["data", "show", "ms.csv"],
     {"ms.csv": csv(t=np.arange(T.size) * 1.0, z=np.interp(np.arange(T.size) / 1000.0, T,
                                                           HEART_MM[:, 0])[:, None]
                    * [1, 1, 1])},
     2, r"rhmpc data: error: ms\.csv: the times look like|rhmpc data: error: ms\.csv: one "),
    ("data-frame-numbers", ["data", "show", "frames.csv"],
     {"frames.csv": csv(t=np.arange(T.size) * 1.0)},
     2, r"rhmpc data: error: frames\.csv: the times look like frame numbers \(steps of 1\)"),
    ("predict-trials-huge", ["predict", "--study", "noise", "--trials", "1000000000"], {},
     2, r"rhmpc predict: error: --trials: 1000000000 Monte Carlo trials would take about .* "
        r"at most \d+ fit in 2 GiB of memory and a day of computing$"),
    ("sim-horizon-huge", [*SIM, "--set", "mpc.horizon=100000", "--set", "mpc.blocks=[100000]"],
     {}, 2, r"rhmpc simulate: error: mpc\.horizon: 100000 MPC horizon steps would take about "
            r".*; at most \d+ fit in 2 GiB of memory and a day of computing$"),
]


def _spike_is_excluded(root: Path, out: str) -> None:
    doc = json.loads(out)
    assert math.isfinite(doc["rms_error_mm"]) and doc["rms_error_mm"] < 5
    excluded = doc["excluded"]  # the spike leaves the score, as a non-measurement or outlier
    assert excluded["unmeasured"] + excluded["outliers"] >= 1, excluded


def _users_file_kept(root: Path, out: str) -> None:
    assert (root / "out" / "notes.txt").read_text() == "mine\n"
    assert sorted(p.name for p in (root / "out").iterdir()) == ["notes.txt"]


def _file_kept(root: Path, out: str) -> None:
    assert (root / "e.csv").read_text() == "mine\n"


#: Checks beyond the exit code and stderr: on the working directory and stdout.
def _input_kept(root: Path, out: str) -> None:
    scipy.io.loadmat(root / "rec.mat")  # still the recording


def _victim_kept(root: Path, out: str) -> None:
    assert (root / "victim.h").read_text() == "keep\n"
    assert sorted(p.name for p in (root / "out").iterdir()) == ["rhmpc.h"]


CHECKS: dict[str, Callable[[Path, str], None]] = {
    "sim-out-is-input": _input_kept,
    "export-through-link": _victim_kept,
    "sim-data-spike": _spike_is_excluded,
    "export-over-users-file": _users_file_kept,
    "data-export-over-file": _file_kept,
}

#: A tqdm progress line: ``DESC:  50%|█████     | 2.00k/4.00k [00:01<00:01, 3.7ktick/s]``.
_PROGRESS = re.compile(r"\d+%\|.*\|.*\[.*\]\s*$")
_WARNING = re.compile(r"rhmpc [\w ]+: warning: ")
_ERROR = re.compile(r"rhmpc [\w ]+: error: ")


def message_lines(err: str) -> list[str]:
    """The lines of ``err`` that say something: no progress bars, no argparse usage block."""
    lines, usage = [], False
    for raw in err.replace("\r", "\n").splitlines():
        line = raw.rstrip()
        if line.startswith("usage: "):
            usage = True
            continue
        if usage and (line.startswith(" ") or not line):
            continue
        usage = False
        if line.strip() and not _PROGRESS.search(line):
            lines.append(line)
    return lines


def _write(root: Path, files: dict[str, Content]) -> None:
    for name, content in files.items():
        path = root / name
        if content is None:
            path.mkdir(parents=True)
        elif isinstance(content, bytes):
            path.write_bytes(content)
        elif isinstance(content, str):
            path.write_text(content)
        else:
            content(path)


def _param(case):
    return case if hasattr(case, "marks") else pytest.param(*case[1:], id=case[0])


@pytest.mark.parametrize(("argv", "files", "code", "first_line"), [_param(c) for c in CASES])
def test_bad_input(request: pytest.FixtureRequest, tmp_path: Path,
                   monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                   argv: list[str], files: dict[str, Content], code: int,
                   first_line: str | None) -> None:
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, files)
    try:
        got = main(argv)
    except SystemExit as exc:  # argparse's own refusals
        got = exc.code
    out, err = capsys.readouterr()
    assert "Traceback" not in err, err
    assert got == code, err
    lines = message_lines(err)
    if first_line is None:
        assert not lines, err
    else:
        assert lines and re.match(first_line, lines[0]), err
    if code == 2:  # one error line, the last; before it, one-line warnings only
        assert [line for line in lines if _ERROR.match(line)] == lines[-1:], err
        assert all(_WARNING.match(line) for line in lines[:-1]), err
    else:
        assert not any(_ERROR.match(line) for line in lines), err
    case_id = request.node.callspec.id
    if case_id in CHECKS:
        CHECKS[case_id](tmp_path, out)
