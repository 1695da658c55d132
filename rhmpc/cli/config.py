"""`rhmpc config show`: every setting of a run, with its default, unit and source, as TOML.

The output is a run file: ``rhmpc simulate --config FILE.toml`` reads it back to the same
settings. Values are the effective ones (defaults < ``--config`` < ``--preset`` < ``--set``);
the comment above each key gives its description, unit, default and where its value comes
from. Descriptions and units come from the settings classes' numpydoc ``Attributes`` sections,
where every unit is stated in brackets (``[m]``, ``[rad/s]``, ``[-]``).
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import textwrap
from typing import Any

from rhmpc.cli import COMMANDS
from rhmpc.cli.presets import add_preset_option
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig
from rhmpc.experiment.config import FREE_TABLES, SECTIONS, parse_sets, read_toml
from rhmpc.experiment.presets import PRESETS, apply_preset

#: Top-level keys of a run file that hold tables of free keys: the recording's read options and
#: the configuration's free tables.
TABLES: tuple[str, ...] = ("data_read", *FREE_TABLES)
#: Longest description kept in a comment [characters].
DESCRIPTION_CHARS = 96

_ATTRIBUTES = re.compile(r"^Attributes\n-+\n(?P<body>.*?)(?=^\S[^\n]*\n-+\n|\Z)", re.S | re.M)
_ENTRY = re.compile(r"^(?P<names>\w+(?:\s*,\s*\w+)*)(?:\s*:\s*(?P<type>.*))?$")
_UNIT = re.compile(r"(?<!\S)\[([^\[\],;=]{1,40})\]")
#: A sentence ends at ". " before a capital letter, except after e.g., i.e. and et al.
_SENTENCE_END = re.compile(r"(?<!e\.g)(?<!i\.e)(?<!et al)\.\s+(?=[A-Z(])")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "config", help=COMMANDS["config"],
        description="Print every setting of a closed-loop run as TOML, with its description, "
        "unit, default and source in comments; `rhmpc simulate --config FILE.toml` reads it "
        "back. Values: defaults < --config < --preset < --set.")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    show = actions.add_parser("show", help="print the settings as TOML")
    show.add_argument("--config", metavar="FILE.toml", help="start from this run file")
    add_preset_option(show)
    show.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                      help="override one setting (repeatable), as in rhmpc simulate")
    show.add_argument("--long", action="store_true",
                      help="each setting's whole description, not its first sentence")
    p.set_defaults(func=run, action=None)


def attribute_docs(cls: type) -> dict[str, tuple[str, str]]:
    """name → (type, description) from the numpydoc ``Attributes`` of ``cls`` and its bases."""
    out: dict[str, tuple[str, str]] = {}
    for klass in reversed(cls.__mro__):
        match = _ATTRIBUTES.search(inspect.getdoc(klass) or "")
        if not match:
            continue
        names: list[str] = []
        for line in match.group("body").splitlines():
            entry = _ENTRY.match(line) if line and not line[0].isspace() else None
            if entry:
                names = [n.strip() for n in entry.group("names").split(",")]
                for name in names:
                    out[name] = ((entry.group("type") or "").strip(), "")
            elif names and line.strip():
                for name in names:
                    kind, text = out[name]
                    out[name] = (kind, f"{text} {line.strip()}".strip())
    return out


def unit_of(description: str) -> str | None:
    """The unit a description states in brackets, or ``None``.

    The first bracket after a space that reads as a unit (no comma, semicolon or equals sign:
    not ``R[0]``, not ``[0, 1)``), skipping one right after a ````literal````, which gives that
    expression's unit rather than the field's.
    """
    for match in _UNIT.finditer(description):
        if not description[: match.start()].rstrip().endswith("``"):
            return match.group(1).replace("``", "").strip()
    return None


def summary(description: str, long: bool = False) -> str:
    """The description's first sentence (``long``: all of it), without units and markup; the
    short form at most DESCRIPTION_CHARS, cut at a word."""
    text = description if long else _SENTENCE_END.split(description, maxsplit=1)[0].rstrip(".")
    text = re.sub(r":\w+:`~?([^`]+)`", r"\1", text)  # Sphinx roles: their target's name
    text = re.sub(r"\s+", " ", _UNIT.sub("", text).replace("``", "")).strip()
    for mark in ",.;:":
        text = text.replace(f" {mark}", mark)
    if long or len(text) <= DESCRIPTION_CHARS:
        return text
    return text[: DESCRIPTION_CHARS].rsplit(" ", 1)[0] + " … (--long)"


def _flat(config: RunConfig) -> dict[str, Any]:
    """Dotted key → value of every setting (``None`` for unset ones)."""
    out: dict[str, Any] = {}
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if f.name in SECTIONS:
            out.update({f"{f.name}.{g.name}": getattr(value, g.name)
                        for g in dataclasses.fields(value)})
        elif f.name in TABLES:
            out.update({f"{f.name}.{k}": v for k, v in value.items()})
        else:
            out[f.name] = value
    return out


def _file_keys(data: dict, prefix: str = "") -> list[str]:
    """Dotted keys of a parsed run file."""
    keys = []
    for key, value in data.items():
        if isinstance(value, dict):
            keys += _file_keys(value, f"{prefix}{key}.")
        else:
            keys.append(prefix + key)
    return keys


def effective(args: argparse.Namespace) -> tuple[RunConfig, RunConfig, dict[str, str]]:
    """(the run's settings, the defaults, dotted key → where its value was set)."""
    defaults = RunConfig()
    sources: dict[str, str] = {}
    config = defaults
    if args.config:
        data = read_toml(args.config)
        config = RunConfig.from_dict(data, where=str(args.config))
        sources.update({k: f"config {args.config}" for k in _file_keys(data)})
    if args.preset:
        config = apply_preset(config, args.preset)
        sources.update({k: f"preset {args.preset}" for k in PRESETS[args.preset]})
    changes = parse_sets(args.set)
    config = config.replace(**changes)
    sources.update({k: "--set" for k in changes})
    return config, defaults, sources


def _value(value: Any) -> str:
    """A TOML value (tomli_w's spelling, so that it reads back the same)."""
    import tomli_w

    if isinstance(value, tuple | list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return tomli_w.dumps({"v": value}).partition("=")[2].strip()


def _key_lines(key: str, name: str, value: Any, default: Any, doc: tuple[str, str] | None,
               source: str | None, long: bool = False) -> list[str]:
    """The comment line(s) and the ``name = value`` line of one setting."""
    text = summary(doc[1], long) if doc else ""
    unit = unit_of(doc[1]) if doc else None
    head = " ".join(part for part in (text, f"[{unit}]" if unit else "") if part)
    notes = ("default " + ("unset" if default is None else _value(default))
             + f", source: {source or 'default'}")
    comment = f"# {head} — {notes}" if head else f"# {notes}"
    if long:
        comment = "\n".join(textwrap.wrap(comment, 100, subsequent_indent="#   "))
    if value is None:
        return [comment, f"# {name} =   (unset)"]
    return [comment, f"{name} = {_value(value)}"]


def render(config: RunConfig, defaults: RunConfig, sources: dict[str, str],
           long: bool = False) -> str:
    """The run's settings as commented TOML (module docstring); ``long``: whole descriptions."""
    flat, base = _flat(config), _flat(defaults)
    docs = attribute_docs(RunConfig)
    lines = ["# rhmpc run settings. Above each key: its description [unit] — default, source.",
             "# Read back with: rhmpc simulate --config FILE.toml", ""]
    for f in dataclasses.fields(config):
        if f.name not in SECTIONS and f.name not in TABLES:
            lines += _key_lines(f.name, f.name, flat[f.name], base[f.name], docs.get(f.name),
                                sources.get(f.name), long)
    for table in TABLES:
        lines += ["", f"[{table}]", f"# {summary(docs[table][1])}"]
        lines += _table_lines(config, table, flat, sources)
    for section in SECTIONS:
        lines += _section_lines(section, getattr(config, section), flat, base, sources, long)
    return "\n".join(lines) + "\n"


def _section_lines(section: str, settings: Any, flat: dict[str, Any], base: dict[str, Any],
                   sources: dict[str, str], long: bool) -> list[str]:
    """A section's table: each setting with its comment."""
    cls = type(settings)
    lines = ["", f"[{section}]", f"# {cls.__module__}.{cls.__qualname__}"]
    docs = attribute_docs(cls)
    for g in dataclasses.fields(cls):
        key = f"{section}.{g.name}"
        lines += _key_lines(key, g.name, flat[key], base[key], docs.get(g.name),
                            sources.get(key), long)
    return lines


def _table_lines(config: RunConfig, table: str, flat: dict[str, Any],
                 sources: dict[str, str]) -> list[str]:
    """The keys set in a free table; for ``predictor_settings`` also the predictor's other
    settings with their defaults, commented out."""
    lines: list[str] = []
    prefix = f"{table}."
    docs: dict[str, tuple[str, str]] = {}
    defaults: dict[str, Any] = {}
    if table == "predictor_settings":
        from rhmpc.predictors import settings_for

        made = settings_for(config.predictor)
        cls = type(made)
        docs = attribute_docs(cls)
        defaults = {g.name: getattr(made, g.name) for g in dataclasses.fields(made)}
        lines.append(f"# {config.predictor}: {cls.__module__}.{cls.__qualname__}")
    for key, value in flat.items():
        if key.startswith(prefix):
            name = key[len(prefix):]
            lines += _key_lines(key, name, value, defaults.get(name), docs.get(name),
                                sources.get(key))
    for name, default in defaults.items():
        if f"{prefix}{name}" not in flat and _tomlable(default):
            doc = docs.get(name)
            unit = unit_of(doc[1]) if doc else None
            text = f"{summary(doc[1])} " if doc else ""
            line = f"# {name} = {_value(default)}   # {text}" + (f"[{unit}]" if unit else "")
            lines.append(line.rstrip())
    return lines


def _tomlable(value: Any) -> bool:
    if isinstance(value, bool | int | float | str):
        return True
    return isinstance(value, tuple) and all(isinstance(v, int | float | str) for v in value)


def run(args: argparse.Namespace) -> int:
    if args.action is None:
        raise UsageError("choose an action: show")
    config, defaults, sources = effective(args)
    print(render(config, defaults, sources, args.long), end="")
    return 0
