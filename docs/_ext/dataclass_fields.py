"""Sphinx extension: every field of a dataclass documented on its class's API page.

The settings classes document their fields in numpydoc ``Attributes`` sections, each with its
unit in brackets; a subclass documents only the fields it adds (``GeneralizedSettings`` adds
``order`` and ``points`` to the six of ``RLSCommon`` and the one of ``PredictorSettings``). Left
to numpydoc and autodoc, a page would list a subclass's own entries only, and then each own field
a second time as a bare ``name = default`` member without its description.

For every dataclass, this extension instead writes one ``py:attribute`` entry per field, in the
order of the constructor's parameters, inherited fields included:

* the type and the description from the nearest ``Attributes`` entry in the class's MRO (or,
  for a field no section describes, its annotation and its ``#:`` comment, if any);
* the default value, or ``ClassName()`` for a ``default_factory`` that is a class.

Field entries leave the ``Attributes`` section before numpydoc renders it (entries that are not
fields, such as properties, stay), and autodoc's own members for the fields are skipped, so that
each field is described once and is a cross-reference target
(``:attr:`~rhmpc.sim.loop.settings.LoopSettings.duration```) wherever it was defined.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
from typing import Any

from sphinx.application import Sphinx
from sphinx.errors import PycodeError
from sphinx.pycode import ModuleAnalyzer

#: A numpydoc section header: a title line followed by a line of dashes.
_DASHES = re.compile(r"^-{3,}\s*$")
#: ``name : type`` or ``name1, name2 : type`` at the start of an ``Attributes`` entry.
_ENTRY = re.compile(r"^(?P<names>\*{0,2}\w+(?:\s*,\s*\w+)*)\s*(?::\s*(?P<type>.*))?$")
#: An rST comment that marks a class body whose fields are already appended.
_MARK = ".. fields of the dataclass follow"
#: Longest default shown in an entry's signature [characters]; longer ones are left out.
MAX_VALUE_CHARS = 60


def _section_span(lines: list[str], title: str) -> tuple[int, int] | None:
    """Start and end (exclusive) of the section ``title`` in numpydoc ``lines``, or None."""
    start = None
    for i in range(len(lines) - 1):
        if lines[i].strip() and not lines[i][0].isspace() and _DASHES.match(lines[i + 1]):
            if start is not None:
                return start, i
            if lines[i].strip() == title:
                start = i
    return (start, len(lines)) if start is not None else None


#: An ``Attributes`` entry: names, type, description lines, its first line and its end line.
_Entry = tuple[list[str], str, list[str], int, int]


def _entries(lines: list[str], span: tuple[int, int]) -> list[_Entry]:
    """The entries of the section at ``span`` of ``lines``."""
    out: list[_Entry] = []
    for i in range(span[0] + 2, span[1]):
        line = lines[i]
        head = _ENTRY.match(line) if line.strip() and not line[0].isspace() else None
        if head:
            names = [n.strip() for n in head.group("names").split(",")]
            out.append((names, (head.group("type") or "").strip(), [], i, i + 1))
        elif out:
            names, kind, desc, first, _ = out[-1]
            out[-1] = (names, kind, [*desc, line], first, i + 1)
    return [(n, k, inspect.cleandoc("\n".join(d)).splitlines(), a, b) for n, k, d, a, b in out]


def _attribute_docs(klass: type) -> dict[str, tuple[str, list[str]]]:
    """name → (type, description lines) from the ``Attributes`` section of ``klass`` itself."""
    lines = (inspect.getdoc(klass) or "").splitlines() if "__doc__" in vars(klass) else []
    span = _section_span(lines, "Attributes")
    if span is None:
        return {}
    return {name: (kind, desc) for names, kind, desc, _, _ in _entries(lines, span)
            for name in names}


def _comment_docs(klass: type) -> dict[str, list[str]]:
    """name → the ``#:`` comment above a field of ``klass`` in its source."""
    try:
        analyzer = ModuleAnalyzer.for_module(klass.__module__)
        docs = analyzer.find_attr_docs()
    except PycodeError:
        return {}
    return {name: list(lines) for (ns, name), lines in docs.items() if ns == klass.__qualname__}


def _default(field: dataclasses.Field) -> str | None:
    """The default as it would be written in a call, or None if there is none (or too long)."""
    if field.default is not dataclasses.MISSING:
        text = repr(field.default)
    elif field.default_factory is not dataclasses.MISSING:
        factory = field.default_factory
        if isinstance(factory, type) and dataclasses.is_dataclass(factory):
            text = f"{factory.__name__}()"
        else:
            try:
                text = repr(factory())
            except Exception:  # a factory that needs the environment: no default shown
                return None
    else:
        return None
    return text if len(text) <= MAX_VALUE_CHARS and "\n" not in text else None


def _fields(cls: type) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(cls) if not f.name.startswith("_")]


def field_entries(cls: type) -> list[str]:
    """reST: one ``py:attribute`` directive per public field of the dataclass ``cls``."""
    mro = [k for k in cls.__mro__ if dataclasses.is_dataclass(k)]
    documented = [_attribute_docs(k) for k in mro]  # nearest class first
    out: list[str] = []
    for field in _fields(cls):
        owner = next((k for k in mro if field.name in vars(k).get("__annotations__", {})), cls)
        kind, desc = next((d[field.name] for d in documented if field.name in d),
                          ("", _comment_docs(owner).get(field.name, [])))
        kind = kind or (field.type if isinstance(field.type, str) else
                        getattr(field.type, "__name__", ""))
        out += ["", f".. py:attribute:: {field.name}"]
        if kind:
            out.append(f"   :type: {kind}")
        value = _default(field)
        if value is not None:
            out.append(f"   :value: {value}")
        out.append("")
        out += [f"   {line}" if line else "" for line in desc]
        if owner is not cls:
            out += ["", f"   (Inherited from :class:`~{owner.__module__}.{owner.__qualname__}`.)"]
    return out


def _is_dataclass_type(obj: Any) -> bool:
    return isinstance(obj, type) and dataclasses.is_dataclass(obj)


def strip_field_entries(app: Sphinx, what: str, name: str, obj: Any, options: Any,
                        lines: list[str]) -> None:
    """Before numpydoc: take the fields' entries out of a dataclass's ``Attributes`` section."""
    if what != "class" or not _is_dataclass_type(obj):
        return
    span = _section_span(lines, "Attributes")
    if span is None:
        return
    fields = {f.name for f in dataclasses.fields(obj)}
    entries = _entries(lines, span)
    kept = [e for e in entries if not set(e[0]) <= fields]
    drop: set[int] = set()
    for _, _, _, first, end in (e for e in entries if set(e[0]) <= fields):
        drop.update(range(first, end))
    if not kept:  # the section held fields only: the header goes too
        drop.update(range(span[0], span[1]))
    # blank lines stay: they separate what is left (the next section's header, kept entries)
    lines[:] = [line for i, line in enumerate(lines) if i not in drop or not line.strip()]


def append_field_entries(app: Sphinx, what: str, name: str, obj: Any, options: Any,
                         lines: list[str]) -> None:
    """After numpydoc: one attribute entry per field at the end of the class's body."""
    if what == "class" and _is_dataclass_type(obj) and _MARK not in lines:
        lines += ["", _MARK, *field_entries(obj)]


def skip_field_members(app: Sphinx, what: str, name: str, obj: Any, skip: bool,
                       options: Any) -> bool | None:
    """Skip autodoc's own member for a field: :func:`append_field_entries` documents it."""
    if what != "class":
        return None
    current = app.env.current_document
    try:
        cls = importlib.import_module(current.autodoc_module)
        for part in current.autodoc_class.split("."):
            cls = getattr(cls, part)
    except (ImportError, AttributeError, ValueError):
        return None
    if _is_dataclass_type(cls) and name in {f.name for f in dataclasses.fields(cls)}:
        return True
    return None


def setup(app: Sphinx) -> dict[str, Any]:
    # numpydoc renders docstrings at the default priority (500): strip before, append after.
    app.connect("autodoc-process-docstring", strip_field_entries, priority=400)
    app.connect("autodoc-process-docstring", append_field_entries, priority=600)
    app.connect("autodoc-skip-member", skip_field_members)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
