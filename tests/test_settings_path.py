"""The path of a run's settings, measured and held to the design page's drawing: the
repository files a command's calls cross on their way from the command line to the loop.

``python -m tests.test_settings_path [rhmpc arguments]`` runs the command (by default the
three ``rhmpc simulate`` runs of :data:`RUNS`) under :func:`sys.setprofile` up to the call of
:func:`rhmpc.sim.loop.run_closed_loop` (the loop itself is not run), ignores library files and the
module bodies an import runs, and prints

- ``files_crossed``, ``returns_crossed``: the repository files entered by any call, and the
  places where a call enters a file already entered from another place (the components'
  own insides included: the MPC's build, the robot's model);
- ``files``: the repository files the settings enter, from the command line
  (``rhmpc.cli.main``) and from ``run_experiment`` on: a call carries the settings when an
  argument is the command's options (their namespace, or a ``dict`` of settings by name), the
  :class:`~rhmpc.experiment.RunConfig`, one of its settings objects (a class named
  ``…Settings``, ``…Config``, ``…Spec`` or ``…Mismatch``; not the call of its own property or
  ``__post_init__``, which reads it where it is declared), or the run's predictor, scenario,
  robot, sensor or recording by name;
- ``entries``: the places in the code (file and line) whose call carries the settings into
  another file, as the run takes them (a call in a loop counts once);
- ``returns``: the entries into a file already entered from another place
  (``entries - files``: each file entered once gives 0);
- ``back_calls``: the entries into a file still open further up the call stack (a file left
  for a lower one and called back);
- ``upward``: the entries from a module into one of a higher layer of the package map
  (``tests/test_layers.py``, ``docs/design/index.md``);
- ``scenarios_entered``, ``heart_returns``: while the heart is built, the entries (whatever
  they carry) into ``sim/heart/scenarios.py``, and the returns among the ``sim/heart`` files;
- ``name_hops``, ``name_files``: the calls that take the predictor's name as an argument, from
  ``run_experiment`` to the predictor's constructor (that call included), and their files;
- ``recording_reads``: the times a recording is read (``load_recording``, ``load_poi``,
  ``load_points`` called from outside ``sim/recordings``).

``--heart-builder NAME`` first names the function whose call builds the heart (default
``build_heart``; ``heart_source`` for a version of the code without it).

The tests below trace the same runs (and one with a saved model) and fail when a hand-off of
the settings leaves the table of ``docs/design/index.md``, when a file calls back up, or when
the heart or the predictor's name take another road.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tests.test_layers import layer_of, module_name

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("rhmpc", "sim", "predictors", "robots")


class _Reached(Exception):
    """Raised at the loop's call: the path is measured, the loop need not run."""


#: The names of the classes whose instances are settings.
SETTINGS_CLASS = re.compile(r"(Settings|Config|Spec|Mismatch)$")


def repo_file(filename: str) -> str | None:
    """``filename`` relative to the repository if it is a file of its packages, else None."""
    try:
        rel = Path(filename).resolve().relative_to(REPO)
    except ValueError:
        return None
    return rel.as_posix() if rel.parts[0] in PACKAGES else None


@dataclass
class Entry:
    """One place where a call enters a file: the caller's file and line (None: from outside),
    the callee's file and function, whether the callee was open further up the stack, and
    what settings its arguments carried (a settings object; the strings among them)."""

    caller: str | None
    line: int
    callee: str
    function: str
    back: bool = False
    settings: bool = False
    strings: set[str] = field(default_factory=set)


def _layer(path: str) -> float | None:
    found = layer_of(module_name(REPO / path, REPO))
    return None if found is None else found[0]


def _carries(value) -> bool:
    """Whether ``value`` is the command's options (its namespace, or a ``dict`` of settings by
    name, top-level or dotted) or a settings object of the repository."""
    from rhmpc.experiment import RunConfig

    cls = type(value)
    if isinstance(value, dict):
        names = {f.name for f in dataclasses.fields(RunConfig)}
        return any(isinstance(k, str) and k.partition(".")[0] in names for k in value)
    return isinstance(value, argparse.Namespace) or (
        dataclasses.is_dataclass(value) and not isinstance(value, type)
        and bool(SETTINGS_CLASS.search(cls.__name__)) and cls.__module__.split(".")[0]
        in PACKAGES)


@dataclass
class Crossing:
    """What a traced command's calls crossed (module docstring)."""

    everything: list[Entry] = field(default_factory=list)  #: every entry, in order
    names: set[str] = field(default_factory=set)  #: the run's names (predictor, scenario...)
    experiment: int = 0  #: the index of ``run_experiment``'s entry
    heart: tuple[int, int] = (0, 0)  #: the entries made while the heart was built
    hops: list[Entry] = field(default_factory=list)  #: the predictor's name's calls
    reads: int = 0  #: the times the recording is read

    @property
    def entries(self) -> list[Entry]:
        """The entries that carry the settings."""
        return [e for e in self.everything if e.settings or e.strings & self.names]

    def files(self, start: int = 0) -> list[str]:
        """The distinct files the settings enter from entry ``start`` of ``everything`` on,
        in the order first entered."""
        return list(dict.fromkeys(e.callee for e in self.everything[start:]
                                  if e.settings or e.strings & self.names))

    def upward(self) -> list[Entry]:
        """The entries into a module of a higher layer than the caller's."""
        return [e for e in self.everything if e.caller is not None and None not in (
            _layer(e.caller), _layer(e.callee)) and _layer(e.callee) > _layer(e.caller)]

    def summary(self) -> dict[str, int]:
        heart = [e for e in self.everything[slice(*self.heart)]
                 if e.callee.startswith("sim/heart/")]
        entries = self.entries
        crossed = {e.callee for e in self.everything}
        return {
            "files_crossed": len(crossed),
            "returns_crossed": len(self.everything) - len(crossed),
            "files": len(self.files()),
            "files_from_experiment": len(self.files(self.experiment)),
            "entries": len(entries),
            "returns": len(entries) - len(self.files()),
            "back_calls": sum(e.back for e in entries),
            "upward": len(self.upward()),
            "scenarios_entered": sum(e.callee == "sim/heart/scenarios.py" for e in heart),
            "heart_returns": len(heart) - len({e.callee for e in heart}),
            "name_hops": len(self.hops),
            "name_files": len({e.callee for e in self.hops}),
            "recording_reads": self.reads,
        }


def trace(argv: list[str], heart_builder: str = "build_heart") -> Crossing:
    """What ``rhmpc`` ``argv`` crosses up to the loop's call (module docstring).

    ``heart_builder``: the function whose call builds the heart (its entries make the heart's
    span).
    """
    from rhmpc.cli import main
    from rhmpc.predictors.base import Predictor
    from rhmpc.sim.loop import run_closed_loop

    loop_code = run_closed_loop.__code__
    out = Crossing()
    seen: dict[tuple, Entry] = {}
    stack: list[tuple[str | None, object]] = []  # (repository file or None, frame)
    state = {"importing": 0, "heart": None, "name": None, "built": False}

    def profile(frame, event, arg):
        if event == "return":
            if frame.f_code.co_name == "<module>":
                state["importing"] -= 1
            if state["heart"] == len(stack):
                out.heart = (out.heart[0], len(out.everything))
                state["heart"] = -1
            if stack:
                stack.pop()
            return
        if event != "call":
            return
        code = frame.f_code
        callee = None if code.co_name == "<module>" else repo_file(code.co_filename)
        state["importing"] += code.co_name == "<module>"
        caller = next(((f, fr) for f, fr in reversed(stack) if f is not None), (None, None))
        stack.append((callee, frame))
        if state["importing"] or callee is None:
            return
        args = list(frame.f_locals.values())
        if code.co_name == "run_experiment" and callee.startswith("rhmpc/experiment/"):
            out.experiment = len(out.everything)
            config = frame.f_locals["config"]
            state["name"] = config.predictor
            out.names = {v for v in (config.predictor, config.scenario, config.robot,
                                     config.sensor, config.data) if v}
        if code.co_name == heart_builder and state["heart"] is None:
            state["heart"] = len(stack)
            out.heart = (len(out.everything), len(out.everything))
        line = caller[1].f_lineno if caller[1] is not None else 0
        if callee != caller[0]:
            key = (caller[0], line, callee)
            entry = seen.get(key)
            if entry is None:
                entry = seen[key] = Entry(caller[0], line, callee, code.co_name,
                                          any(f == callee for f, _ in stack[:-1]))
                out.everything.append(entry)
            # a property or ``__post_init__`` of a settings object reads it where it is
            # declared: the settings do not travel
            alone = code.co_argcount + code.co_kwonlyargcount == 1 and not code.co_flags & 12
            entry.settings |= any(_carries(v) for k, v in frame.f_locals.items()
                                  if not (alone and k == "self"))
            entry.strings |= {v for v in args if isinstance(v, str) and len(v) < 300}
        name = state["name"]
        if name is not None and not state["built"]:
            built = code.co_name == "__init__" and isinstance(frame.f_locals.get("self"),
                                                              Predictor)
            if built or any(isinstance(v, str) and v == name for v in args):
                out.hops.append(Entry(caller[0], line, callee, code.co_name))
            state["built"] = built
        if code.co_name in ("load_recording", "load_points", "load_poi") and callee.startswith(
                "sim/recordings/") and not str(caller[0]).startswith("sim/recordings/"):
            out.reads += 1
        if code is loop_code:
            raise _Reached

    sys.setprofile(profile)
    try:
        main(argv)
    except _Reached:
        pass
    finally:
        sys.setprofile(None)
    return out


def report(argv: list[str], **kwargs) -> str:
    """The counts of :func:`trace` for ``argv``, one per line, then what they count."""
    crossing = trace(argv, **kwargs)
    lines = [f"rhmpc {' '.join(argv)}"]
    lines += [f"  {k:<22} {v}" for k, v in crossing.summary().items()]

    def where(e: Entry) -> str:
        return f"{e.caller}:{e.line} -> {e.callee} {e.function}"

    lines.append("  upward: " + "; ".join(map(where, crossing.upward())))
    lines.append("  back calls: " + "; ".join(where(e) for e in crossing.entries if e.back))
    lines.append("  name hops: " + " -> ".join(f"{Path(e.callee).stem}.{e.function}"
                                              for e in crossing.hops))
    entries = crossing.entries
    lines.append("  files (entries): " + ", ".join(
        f"{f} ({sum(e.callee == f for e in entries)})" for f in crossing.files()))
    lines.append("  heart: " + "; ".join(where(e) for e in crossing.everything[
        slice(*crossing.heart)] if e.callee.startswith("sim/heart/")))
    return "\n".join(lines)


#: The runs measured by default: the main job, a recording, a recording's split with a preset.
RUNS = (
    ["simulate", "--duration", "1", "--settling", "0.5"],
    ["simulate", "--data", "hamlyn-phantom", "--duration", "2", "--settling", "1"],
    ["simulate", "--data", "hamlyn-phantom", "--split", "600:650", "--preset", "tuna2013"],
)

DOC = REPO / "docs" / "design" / "index.md"
#: The chain's files in the order the settings first enter them, each with the file that
#: hands them the settings: the command builds the RunConfig, then runs it (the loop's file
#: may be entered first by a predictor's fitting, which reads the settling window as the loop
#: delivers it).
CHAIN = {"rhmpc/experiment/config.py": "rhmpc/cli/simulate.py",
         "rhmpc/experiment/run.py": "rhmpc/cli/simulate.py",
         "rhmpc/experiment/assembly.py": "rhmpc/experiment/run.py",
         "sim/loop/closed_loop.py": "rhmpc/experiment/run.py"}
#: The files whose hand-offs the design page's table lists.
HANDING = ("rhmpc/cli/simulate.py", *list(CHAIN)[:-1], "sim/sources.py")


def drawn_handoffs(text: str) -> set[tuple[str, str]]:
    """(from, to) of each row of the design page's table of the settings' hand-offs."""
    section = text.split("## The path of a run's settings", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `([^`]+)` \| `([^`]+)` \|", section, re.M)
    return set(rows)


def _drawn(edge: tuple[str, str], drawn: set[tuple[str, str]]) -> bool:
    """Whether ``edge`` is a row of ``drawn`` (a drawn folder standing for its files)."""
    return any(edge[0] == a and (edge[1] == b or (b.endswith("/") and edge[1].startswith(b)))
               for a, b in drawn)


@pytest.fixture(scope="module")
def crossings(tmp_path_factory) -> list[Crossing]:
    """The runs of :data:`RUNS`, then the split's run with a saved ridge model (``--model``)."""
    from rhmpc.cli import main

    folder = tmp_path_factory.mktemp("models")
    assert main(["predict", "--data", "hamlyn-phantom", "--split", "100:150", "--predictors",
                 "ridge", "--save-models", str(folder)]) == 0
    (model,) = sorted(folder.iterdir())
    return [trace(list(argv)) for argv in (*RUNS, [*RUNS[-1], "--predictor", "ridge",
                                                   "--model", str(model)])]


@pytest.mark.slow
def test_the_settings_go_down_the_drawn_chain(crossings: list[Crossing]) -> None:
    """Every hand-off from a file of the chain is a row of the design page's table, and
    every row is taken by one of the runs; the chain's files are first entered in order, from
    the file that hands them the settings; nothing calls back into a file further up the
    stack, and no call goes up a layer."""
    drawn = drawn_handoffs(DOC.read_text(encoding="utf-8"))
    taken = set()
    for crossing in crossings:
        handed = {(e.caller, e.callee) for e in crossing.entries if e.caller in HANDING}
        assert [edge for edge in handed if not _drawn(edge, drawn)] == []
        taken |= {(e.caller, e.callee) for e in crossing.everything}
        first = {}
        for e in crossing.everything:
            first.setdefault(e.callee, e.caller)
        assert [f for f in first if f in CHAIN] == list(CHAIN)
        assert {f: first[f] for f in list(CHAIN)[:-1]} == dict(list(CHAIN.items())[:-1])
        assert [e for e in crossing.everything if e.back and e.caller in HANDING] == []
        assert {(e.caller, e.callee) for e in crossing.upward()} == set()
    assert [row for row in drawn if not any(_drawn(edge, {row}) for edge in taken)] == []


@pytest.mark.slow
def test_a_heart_is_built_in_one_place_and_a_name_resolved_once(
        crossings: list[Crossing]) -> None:
    """The heart is entered once, by the scenario's builder, from the run's heart source; the
    predictor's name reaches its class through the registry's one lookup (``resolve``), and
    a recording is read at most twice (its span, its samples)."""
    scenario, *recordings, _ = crossings
    heart = [e for e in scenario.everything[slice(*scenario.heart)]
             if e.callee.startswith("sim/heart/") and not e.caller.startswith("sim/heart/")]
    assert [(e.caller, e.callee, e.function) for e in heart] == [
        ("sim/sources.py", "sim/heart/scenarios.py", "make_scenario")]
    for crossing in crossings[:-1]:
        names = [(e.callee, e.function) for e in crossing.hops
                 if e.callee.startswith("predictors/")]
        assert names[:3] == [("predictors/registry.py", "make_predictor"),
                             ("predictors/registry.py", "resolve"),
                             ("predictors/registry.py", "_entry")]
        assert sum(f == "resolve" for _, f in names) == 1
        assert {e.callee for e in crossing.hops} <= {"predictors/registry.py",
                                                     "predictors/base.py",
                                                     "rhmpc/experiment/config.py"}
    assert [c.reads for c in recordings] == [1, 2]


def test_the_table_is_read() -> None:
    """The design page's table parses into hand-offs from every file of the chain."""
    drawn = drawn_handoffs(DOC.read_text(encoding="utf-8"))
    assert {a for a, _ in drawn} == set(HANDING)
    assert all((REPO / b).exists() for _, b in drawn)


if __name__ == "__main__":
    builder = "build_heart"
    args = sys.argv[1:]
    if args[:1] == ["--heart-builder"]:
        builder, args = args[1], args[2:]
    for argv in [args] if args else RUNS:
        print(report(list(argv), heart_builder=builder))
