"""The options several commands share: a run's settings (``simulate``, ``compare``, ``sil``), how
to read a recording, the literature's split, saved models, and the host's stalls."""

from __future__ import annotations

import argparse

from rhmpc.cli.presets import add_preset_option
from rhmpc.errors import UsageError
from rhmpc.sim.loop.settings import DEFAULT_SETTLING, LoopSettings

#: Default run length [s] of every command (``LoopSettings.duration``).
DEFAULT_DURATION = LoopSettings.duration
#: The settling rule when neither --settling nor a config file sets it.
SETTLING_RULE = (f"settling by default {DEFAULT_SETTLING:g} s, or a third of a run shorter than "
                 f"{3 * DEFAULT_SETTLING:g} s")


def parse_indices(text: str) -> list[int]:
    """``--rows``/``--cols`` (:func:`rhmpc.sim.recordings.matfile.parse_indices`), its module
    loaded when an option is given, not for ``--help``."""
    from rhmpc.sim.recordings.matfile import parse_indices as parse

    return parse(text)


def add_run_options(
    p: argparse.ArgumentParser,
    duration: float = DEFAULT_DURATION,
    settling: float = DEFAULT_SETTLING,
) -> None:
    """Options shared by ``simulate`` and ``compare`` (``duration``/``settling``: for the help)."""
    p.add_argument("--config", metavar="FILE.toml", help="every setting of the run (TOML)")
    p.add_argument("--robot", help="a robot (rhmpc robots) or robot file X.toml; default phantom")
    p.add_argument("--sensor", help="sonomicrometry (default; the instrument from its "
                   "physics), white (additive white noise), ultrasound, video (stereo video "
                   "tracking, 25 Hz), ideal; 'recorded' uses a "
                   "--data file's samples as they are. Settings: --set sensor_settings.KEY=VALUE "
                   "(e.g. playback=\"offline\", noise=5e-5 for white, crystals=6)")
    p.add_argument("--duration", type=float,
                   help=f"simulated seconds (default {duration:g})")
    p.add_argument("--settling", type=float,
                   help=f"seconds excluded from the metrics (default {settling:g}, or a third "
                   f"of a run shorter than {3 * settling:g} s)")
    p.add_argument("--ground-truth", choices=("recorded", "true"),
                   help="score against the recorded stream (paper protocol, default) or the "
                   "noise-free motion")
    p.add_argument("--rr", metavar="RECORD", help="PhysioNet record whose beat annotations "
                   "drive the heart phase: a shipped name (mitdb-100, 1003) or a path without "
                   "extension")
    add_preset_option(p)
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one setting, e.g. --set mpc.effort_weight=1e-3 (repeatable)")


def add_recording_options(p: argparse.ArgumentParser) -> None:
    """``--var``, ``--rows``, ``--cols``, ``--rate``, ``--units``, ``--topic``, ``--frame``: how
    to read a recording."""
    g = p.add_argument_group("reading a recording (.mat; ROS bags: --topic, --frame)")
    g.add_argument("--var", help="MATLAB variable holding the positions")
    g.add_argument("--rows", type=parse_indices, help="0-based rows holding x,y,z (samples along "
                   "columns), e.g. 0,1,2")
    g.add_argument("--cols", type=parse_indices,
                   help="0-based columns holding x,y,z (samples along rows)")
    g.add_argument("--rate", type=float, dest="data_rate", metavar="HZ",
                   help="sample rate when the file has no time vector [Hz]")
    g.add_argument("--units", choices=("mm", "m", "um", "cm"),
                   help="length unit when the file does not state it (default mm; a ROS bag: m)")
    g.add_argument("--topic", help="a ROS bag's topic of the POI (PoseStamped, PointStamped, "
                   "TransformStamped, tf2_msgs/TFMessage; PoseArray or MarkerArray with --poi)")
    g.add_argument("--frame", help="the child frame read from a tf topic (TFMessage, "
                   "TransformStamped)")



def add_split_option(p: argparse.ArgumentParser, more: str = "") -> None:
    """``--split TRAIN:END``: the literature's split of a recording, in closed loop."""
    p.add_argument("--split", metavar="TRAIN:END", help="with --data: the "
                   "literature's split in closed loop: the run starts at the first sample, a "
                   "predictor fitted before the run learns from the samples before TRAIN (as "
                   "the loop delivers them) and the score covers the instants of samples TRAIN "
                   f"to END - 1 (numbered from 0); replaces --settling and --duration{more}")


def add_model_option(p: argparse.ArgumentParser) -> None:
    """``--model FILE...``: saved models instead of fitting before the run."""
    p.add_argument("--model", nargs="+", metavar="FILE", help="models saved by rhmpc predict "
                   "--save-models, loaded instead of fitted before the run: a fitted "
                   "predictor (ridge, st-ridge, lstm, ...) takes the file of its kind, the "
                   "combination each file into its member of that kind (the others it fits)")


def parse_split(text: str | None) -> tuple[int, int] | None:
    """``--split TRAIN:END`` as (TRAIN, END) sample indices, or ``None``."""
    if text is None:
        return None
    try:
        train, end = (int(v) for v in text.split(":"))
    except ValueError:
        raise UsageError(f"--split {text!r}: expected TRAIN:END frames, e.g. 600:700") from None
    if not 0 < train < end:
        raise UsageError(f"--split {text!r}: expected 0 < TRAIN < END")
    return train, end


def recording_options(args: argparse.Namespace) -> dict:
    """The ``load_recording`` keywords given on the command line."""
    keys = {"var": "var", "rows": "rows", "cols": "cols", "data_rate": "rate", "units": "units",
            "topic": "topic", "frame": "frame"}
    return {v: getattr(args, k) for k, v in keys.items() if getattr(args, k, None) is not None}


#: The longest busy loop ``--host-stalls`` runs [s].
MAX_HOST_STALLS_S = 600.0


def add_host_stalls_option(p: argparse.ArgumentParser, after: str) -> None:
    """``--host-stalls SECONDS``: the host's stalls, timed after ``after``."""
    p.add_argument("--host-stalls", type=float, default=0.0, metavar="SECONDS",
                   help=f"after {after}, time a busy loop for SECONDS and report the host's "
                   "stalls beside the tick's maximum (rhmpc.timing.host.host_stalls; default 0: "
                   "off)")


def check_host_stalls(seconds: float) -> None:
    """A one-line error for a ``--host-stalls`` outside 0 … :data:`MAX_HOST_STALLS_S`."""
    if not 0.0 <= seconds <= MAX_HOST_STALLS_S:
        raise UsageError(f"--host-stalls must be between 0 and {MAX_HOST_STALLS_S:g} s, "
                         f"got {seconds:g}")


def host_stalls_document(seconds: float, gain_us: float | None) -> dict:
    """The host's stalls in a busy loop of ``seconds``, in µs and in gain ticks of ``gain_us``
    (:func:`rhmpc.timing.host.stall_summary`)."""
    from rhmpc.timing.host import host_stalls, stall_summary

    return stall_summary(host_stalls(seconds), seconds, gain_us)
