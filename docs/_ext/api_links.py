"""Sphinx extension: API pages for every module, and cross-references by any public path.

Three things the packages' layout would otherwise cost the API reference:

* **Pages of modules that no longer exist.** autosummary writes a page per module into
  ``_autosummary`` and never removes one; after a module is moved or deleted its old page fails
  to import and breaks the build. Pages of modules that cannot be found are removed first.
* **Modules named like a function.** A package that re-exports a function under its module's
  name (``rhmpc.robots.linearize`` is the module and, in ``rhmpc.robots``, the function) makes
  autosummary document the function where the module's page belongs, and the module's classes
  (``LinearArm``, ``SonomicrometrySettings`` …) on no page at all. A name that is a submodule
  is here resolved to the submodule.
* **References through a re-export.** The API pages document each object where it is defined
  (``rhmpc.sim.loop.results.LoopResult``), while docstrings name it as users import it
  (``rhmpc.sim.loop.LoopResult``, or ``RunConfig`` where the module imported it). A Python reference
  that finds no target is resolved by importing the name it gives, in the module and class it
  is written in, and linking to the page that documents the object it imports (for a constant,
  the one documented name of the same last part that imports to that very object).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from pathlib import Path
from typing import Any

import sphinx.ext.autosummary as autosummary
from docutils import nodes
from sphinx.application import Sphinx
from sphinx.environment import BuildEnvironment
from sphinx.util.nodes import make_refnode

_import_by_name = getattr(autosummary, "_import_by_name", None)


def _submodule_first(name: str, grouped_exception: bool = True) -> tuple[Any, Any, str]:
    """autosummary's import of ``name``, except that a submodule wins over a namesake attribute."""
    found = _import_by_name(name, grouped_exception)
    if not inspect.ismodule(found[0]) and "." in name:
        try:
            is_module = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            is_module = False
        if is_module:
            return importlib.import_module(name), None, name
    return found


def _import(dotted: str) -> Any:
    """The object a dotted path names (its longest importable module, then attributes).

    Only names under a package already imported are tried: a word in a docstring must not
    import some unrelated top-level module.
    """
    parts = dotted.split(".")
    if parts[0] not in sys.modules:
        raise ImportError(dotted)
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for part in parts[i:]:
            obj = getattr(obj, part)
        return obj
    raise ImportError(dotted)


def _canonical(obj: Any) -> str | None:
    """Where ``obj`` is defined: ``module.Qual.Name``, or None for a value without a home."""
    if inspect.ismodule(obj):
        return obj.__name__
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{module}.{qualname}" if isinstance(module, str) and isinstance(qualname, str) else None


def _candidates(node: nodes.Element) -> list[str]:
    """The full names a reference may mean, innermost scope first (as Python would look up)."""
    target = node["reftarget"].lstrip(".~")
    module, cls = node.get("py:module"), node.get("py:class")
    scopes = [s for s in (f"{module}.{cls}" if module and cls else None, module) if s]
    return [*(f"{scope}.{target}" for scope in scopes), target]


def resolve_reexport(app: Sphinx, env: BuildEnvironment, node: nodes.Element,
                     contnode: nodes.Element) -> nodes.Element | None:
    """``missing-reference``: link a Python name to the documented object it imports."""
    if node.get("refdomain") != "py":
        return None
    objects = env.get_domain("py").objects
    for name in _candidates(node):
        head, _, tail = name.rpartition(".")
        try:
            obj = _import(name)
            where = _canonical(obj)
        except (ImportError, AttributeError, ValueError):
            obj = where = None
        if where is None and head:  # a field or a constant: its owner's home, then its name
            try:
                owner = _canonical(_import(head))
            except (ImportError, AttributeError, ValueError):
                owner = None
            where = f"{owner}.{tail}" if owner else None
        if obj is not None and (where is None or where not in objects):
            where = _documented_as(obj, tail or name, objects)  # a constant re-exported
        if where and where != name and where in objects:
            entry = objects[where]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                                contnode, where)
        if obj is not None:
            return None  # the name imports, but its object has no page: no guess
    return None


def _documented_as(obj: Any, last: str, objects: dict[str, Any]) -> str | None:
    """The one documented name ending in ``.last`` that imports to ``obj`` itself, or None."""
    found = []
    for full in objects:
        if full.rpartition(".")[2] == last:
            try:
                if _import(full) is obj:
                    found.append(full)
            except (ImportError, AttributeError, ValueError):
                continue
    return found[0] if len(found) == 1 else None


def _module_exists(name: str) -> bool:
    """Whether the module ``name`` is there (a module that fails to import is there)."""
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError as exc:  # gone with a parent package, or a parent fails
        return not (exc.name and (name == exc.name or name.startswith(f"{exc.name}.")))
    except Exception:  # a parent package that fails to import: the build reports it
        return True


def remove_stale_stubs(app: Sphinx) -> None:
    """``builder-inited``, before autosummary: where a module is gone, delete every page of its
    folder (its package's page lists it too), which autosummary then writes afresh."""
    for folder in Path(app.srcdir).rglob("_autosummary"):
        if Path(app.outdir) in folder.parents:
            continue
        stubs = list(folder.glob("*.rst"))
        if not all(_module_exists(stub.stem) for stub in stubs):
            for stub in stubs:
                stub.unlink()


def setup(app: Sphinx) -> dict[str, Any]:
    # autosummary generates its pages on builder-inited at the default priority (500)
    app.connect("builder-inited", remove_stale_stubs, priority=400)
    if _import_by_name is not None:  # autosummary's internal importer, present since Sphinx 1.x
        autosummary._import_by_name = _submodule_first
    app.connect("missing-reference", resolve_reexport)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
