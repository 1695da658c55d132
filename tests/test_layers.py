"""The import layering of the package map (docs/design/index.md): an import may only point down.

Layers, from the bottom (peers of one layer do not import each other):

-1. ``rhmpc.io``, the one guarded reader, the one atomic writer and the table of bounds, which
    every package may import (it imports the standard library and NumPy only)
0. ``rhmpc.robots``, ``rhmpc.predictors``
0.9 ``rhmpc.errors``, ``rhmpc.compiled`` (the one build helper of every compiled piece) and
    ``rhmpc.positions`` (the truth held in an array, the embedding in 3-D), which every part
    above may use, each other included
1. ``rhmpc.control``, the controller a robot runs
2. ``rhmpc.sim``, the world a controller is run in, itself in floors: ``rhmpc.sim.heart``
   and ``rhmpc.sim.plant``; ``rhmpc.sim.recordings`` and ``rhmpc.sim.sensors`` (they read
   ``rhmpc.sim.heart``'s motion sources); ``rhmpc.sim.sources`` (a scenario or a recording);
   ``rhmpc.sim.loop``. It never imports ``rhmpc.control`` (:data:`INDEPENDENT`): the loop runs
   any controller behind ``refresh`` and ``step``, and the experiment composes the two
2.5 ``rhmpc.timing``, the instruments a run's timing is measured with (the gain tick, the
    host's stalls)
3. ``rhmpc.experiment``
4. the rooms built on runs: ``rhmpc.report`` (one run's report and figures), ``rhmpc.bench``,
   ``rhmpc.openloop`` (the predictors open loop), ``rhmpc.motion`` (heart motion described),
   ``rhmpc.tuning``
4.5 ``rhmpc.compare`` and ``rhmpc.runtime`` (the deployment's processes), which run through
    the tuning's processes that die with their parent
4.7 ``rhmpc.paper``, the published tables beside ``rhmpc.compare``'s cells
5. ``rhmpc.cli``

Every ``import`` statement counts, including those inside functions (deferred imports are
still dependencies), and no module may reach itself through imports (no cycle).
``rhmpc.predictors`` also depends on nothing outside numpy, scipy, the standard library and
``rhmpc.io``, so that a predictor can be lifted into another project; only the learned
predictors (``rhmpc.predictors.learned``) import their optional deep-learning extra, and only
when asked for; likewise only the ROS 2 bridges (``rhmpc.runtime.ros2``) import ``cyclonedds``.

``rhmpc.robots``, ``rhmpc.predictors`` and ``rhmpc.sim`` keep their folders at the repository's
root (``robots/``, ``predictors/``, ``sim/``; pyproject.toml's ``package-dir``): a file's module
is named from :data:`FOLDERS`.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: (package prefix, layer, peer group); the longest matching prefix decides.
LAYERS: tuple[tuple[str, float, str], ...] = (
    ("rhmpc.io", -1, "rhmpc.io"),
    ("rhmpc.robots", 0, "rhmpc.robots"),
    ("rhmpc.predictors", 0, "rhmpc.predictors"),
    ("rhmpc.errors", 0.9, "rhmpc.errors"),
    ("rhmpc.compiled", 0.9, "rhmpc.compiled"),
    ("rhmpc.positions", 0.9, "rhmpc.positions"),
    ("rhmpc.control", 1, "rhmpc.control"),
    ("rhmpc.sim", 2, "rhmpc.sim"),
    ("rhmpc.sim.heart", 2.0, "rhmpc.sim.heart"),
    ("rhmpc.sim.plant", 2.0, "rhmpc.sim.plant"),
    ("rhmpc.sim.recordings", 2.1, "rhmpc.sim.recordings"),
    ("rhmpc.sim.sensors", 2.1, "rhmpc.sim.sensors"),
    ("rhmpc.sim.sources", 2.2, "rhmpc.sim.sources"),
    ("rhmpc.sim.loop", 2.3, "rhmpc.sim.loop"),
    ("rhmpc.timing", 2.5, "rhmpc.timing"),
    ("rhmpc.experiment", 3, "rhmpc.experiment"),
    ("rhmpc.report", 4, "rhmpc.report"),
    ("rhmpc.bench", 4, "rhmpc.bench"),
    ("rhmpc.openloop", 4, "rhmpc.openloop"),
    ("rhmpc.motion", 4, "rhmpc.motion"),
    ("rhmpc.tuning", 4, "rhmpc.tuning"),
    ("rhmpc.compare", 4.5, "rhmpc.compare"),
    ("rhmpc.runtime", 4.5, "rhmpc.runtime"),
    ("rhmpc.paper", 4.7, "rhmpc.paper"),
    ("rhmpc.cli", 5, "rhmpc.cli"),
)
#: The peer groups of layer 0.9 that every part above may import, each other included.
SHARED = ("rhmpc.errors", "rhmpc.compiled", "rhmpc.positions")
#: Pairs of packages neither of which imports the other, whatever their layers.
INDEPENDENT = (("rhmpc.sim", "rhmpc.control"),)
#: The folders of the repository's packages and the module each holds.
FOLDERS = {"robots": "rhmpc.robots", "predictors": "rhmpc.predictors", "sim": "rhmpc.sim",
           "rhmpc": "rhmpc"}
PACKAGES = tuple(FOLDERS)
#: What ``rhmpc.predictors`` may import besides itself and the standard library.
PREDICTOR_DEPENDENCIES = ("numpy", "scipy", "rhmpc.io")
#: What ``rhmpc.io`` may import besides itself and the standard library.
IO_DEPENDENCIES = ("numpy",)
#: The optional extra the learned predictors (``rhmpc.predictors.learned``) may import besides.
LEARNED_DEPENDENCIES = ("torch",)
#: Optional extras imported by one package only (PyTorch: the predictors' rule above).
EXTRAS = {"cyclonedds": "rhmpc.runtime.ros2"}


def within(module: str, package: str) -> bool:
    """Whether ``module`` is ``package`` or one of its submodules (or names in them)."""
    return module == package or module.startswith(package + ".")


def allowed(target: str, own: str, dependencies: tuple[str, ...]) -> bool:
    """Whether ``target`` is in package ``own``, in one of ``dependencies`` or the stdlib."""
    return (within(target, own) or any(within(target, d) for d in dependencies)
            or target.split(".")[0] in sys.stdlib_module_names)


def layer_of(module: str) -> tuple[float, str] | None:
    """(layer, peer group) of a first-party module, or None for third-party/stdlib ones."""
    best = None
    for prefix, layer, group in LAYERS:
        if within(module, prefix) and (best is None or len(prefix) > len(best[0])):
            best = (prefix, layer, group)
    return None if best is None else best[1:]


def module_name(path: Path, root: Path) -> str:
    """The module a file under ``root`` is installed as (``sim/loop/x.py``: rhmpc.sim.loop.x)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    parts[0] = FOLDERS.get(parts[0], parts[0])
    return ".".join(parts)


def imports_of(path: Path, module: str) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in ``path`` (relative imports resolved)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.extend((node.lineno, alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            # ``from rhmpc.tuning import spec`` imports the submodule rhmpc.tuning.spec
            out.extend((node.lineno, f"{base}.{alias.name}") for alias in node.names)
    return out


def violations(root: Path) -> list[str]:
    """Every import under ``root`` that points up a layer or across to a peer."""
    found = []
    for top in PACKAGES:
        for path in sorted((root / top).rglob("*.py")):
            module = module_name(path, root)
            if module == "rhmpc":
                continue  # the facade: lazy re-exports only, resolved on first use
            own = layer_of(module)
            for line, target in imports_of(path, module):
                if within(module, "rhmpc.io") and not allowed(target, "rhmpc.io",
                                                               IO_DEPENDENCIES):
                    found.append(f"{path.relative_to(root)}:{line}: rhmpc.io imports "
                                 f"{target} (the standard library and numpy only)")
                if within(module, "rhmpc.predictors"):
                    extra = LEARNED_DEPENDENCIES if within(module, "rhmpc.predictors.learned") \
                        else ()
                    if not allowed(target, "rhmpc.predictors", (*PREDICTOR_DEPENDENCIES, *extra)):
                        found.append(f"{path.relative_to(root)}:{line}: rhmpc.predictors "
                                     f"imports {target} (numpy, scipy and rhmpc.io only)")
                extra = EXTRAS.get(target.split(".")[0])
                if extra is not None and not within(module, extra):
                    found.append(f"{path.relative_to(root)}:{line}: {module} imports {target} "
                                 f"(an optional extra: {extra} only)")
                if target.split(".")[0] == "rhmpc" and layer_of(target) is None \
                        and target not in ("rhmpc", "rhmpc.__version__"):
                    found.append(f"{path.relative_to(root)}:{line}: {module} imports {target} "
                                 "through the rhmpc facade; import it from its subpackage")
                    continue
                theirs = layer_of(target)
                if own is None or theirs is None or theirs[1] == own[1]:
                    continue
                if theirs[0] > own[0] or (theirs[0] == own[0] and theirs[1] not in SHARED):
                    found.append(f"{path.relative_to(root)}:{line}: {module} (layer {own[0]}) "
                                 f"imports {target} (layer {theirs[0]})")
                for a, b in INDEPENDENT:
                    if (within(module, a) and within(target, b)) or (within(module, b)
                                                                      and within(target, a)):
                        found.append(f"{path.relative_to(root)}:{line}: {module} imports "
                                     f"{target} ({a} and {b} import neither the other)")
    return found


@pytest.mark.slow
def test_no_import_points_up_a_layer() -> None:
    assert violations(REPO) == []


def test_every_module_has_a_layer() -> None:
    unplaced = [module_name(p, REPO) for top in PACKAGES for p in (REPO / top).rglob("*.py")
                if layer_of(module_name(p, REPO)) is None and module_name(p, REPO) != "rhmpc"]
    assert unplaced == [], ("add these modules' package to LAYERS and to the map in "
                            "docs/design/index.md")


@pytest.mark.parametrize(("where", "source", "expected"), [
    ("rhmpc/control/bad.py", "from rhmpc.sim.loop import run_closed_loop\n", "layer 2"),
    ("rhmpc/control/bad.py", "def f():\n    from rhmpc.experiment import run_experiment\n",
     "layer 3"),
    ("rhmpc/bench/bad.py", "from rhmpc.tuning import spec\n", "layer 4"),
    ("rhmpc/compare/bad.py", "from rhmpc.paper.tables import paper_table\n", "layer 4.7"),
    ("rhmpc/tuning/bad.py", "from ..cli import main\n", "layer 5"),
    ("robots/bad.py", "import rhmpc.predictors\n", "layer 0"),
    ("predictors/bad.py", "import pinocchio\n", "numpy, scipy and rhmpc.io only"),
    ("predictors/bad.py", "import torch\n", "numpy, scipy and rhmpc.io only"),
    ("rhmpc/io/bad.py", "import scipy\n", "the standard library and numpy only"),
    ("rhmpc/control/bad.py", "from rhmpc import run_experiment\n", "facade"),
    ("sim/loop/bad.py", "from rhmpc.control.reference import ExactReference\n",
     "import neither the other"),
    ("rhmpc/cli/bad.py", "def f():\n    import cyclonedds.domain\n", "rhmpc.runtime.ros2 only"),
])
def test_the_check_catches_an_upward_import(tmp_path: Path, where: str, source: str,
                                            expected: str) -> None:
    for top in PACKAGES:
        (tmp_path / top).mkdir()
    (tmp_path / where).parent.mkdir(parents=True, exist_ok=True)
    (tmp_path / where).write_text(source)
    found = violations(tmp_path)
    assert found and any(expected in f for f in found), found


def test_allowed_imports_pass(tmp_path: Path) -> None:
    for top in PACKAGES:
        (tmp_path / top).mkdir()
    (tmp_path / "rhmpc" / "cli").mkdir()
    (tmp_path / "rhmpc" / "cli" / "ok.py").write_text(
        "from rhmpc import __version__\nfrom rhmpc.errors import UsageError\n"
        "from rhmpc.tuning.spec import load_spec\nfrom rhmpc.sim.loop import run_closed_loop\n")
    (tmp_path / "predictors" / "ok.py").write_text("import math\nimport numpy as np\n"
                                                   "from scipy import linalg\n"
                                                   "from rhmpc import io\n")
    assert violations(tmp_path) == []


def modules(root: Path) -> dict[str, Path]:
    """Every first-party module under ``root``, by name."""
    return {module_name(p, root): p for top in PACKAGES for p in sorted((root / top).rglob("*.py"))}


def import_graph(root: Path) -> dict[str, set[str]]:
    """module → the first-party modules it imports (the longest module prefix of each target;
    a module's imports of its own parent packages are left out: a package runs its children)."""
    mods = modules(root)
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, path in mods.items():
        for _, target in imports_of(path, m):
            while target and target not in mods:
                target = target.rpartition(".")[0]
            if target and target != m and not m.startswith(target + "."):
                graph[m].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_import_cycle() -> None:
    assert cycles(import_graph(REPO)) == []


def test_the_cycle_check_catches_a_deferred_cycle(tmp_path: Path) -> None:
    for top in PACKAGES:
        (tmp_path / top).mkdir()
    (tmp_path / "sim" / "a.py").write_text("from rhmpc.sim.b import g\n")
    (tmp_path / "sim" / "b.py").write_text("def g():\n    from rhmpc.sim import a\n"
                                           "    return a\n")
    assert cycles(import_graph(tmp_path)) == [["rhmpc.sim.a", "rhmpc.sim.b"]]


def part_of(module: str) -> str:
    """The part (the longest prefix in :data:`LAYERS`) a module belongs to, or the module."""
    prefixes = [prefix for prefix, _, _ in LAYERS if within(module, prefix)]
    return max(prefixes, key=len) if prefixes else module


def parts_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The module graph collapsed to parts: part → the other parts its modules import."""
    out: dict[str, set[str]] = {}
    for module, targets in graph.items():
        out.setdefault(part_of(module), set()).update(part_of(t) for t in targets)
    for part, targets in out.items():
        targets.discard(part)
        for t in targets:
            out.setdefault(t, set())
    return out


@pytest.mark.slow
def test_no_cycle_between_parts() -> None:
    """No part reaches itself through another (``rhmpc.sim`` and ``rhmpc.experiment``, say), even
    where no single module does."""
    assert cycles(parts_graph(import_graph(REPO))) == []


def test_the_parts_check_catches_a_cycle_between_parts(tmp_path: Path) -> None:
    for top in PACKAGES:
        (tmp_path / top).mkdir()
    (tmp_path / "sim" / "loop").mkdir()
    (tmp_path / "sim" / "loop" / "a.py").write_text("from rhmpc.experiment import b\n")
    (tmp_path / "rhmpc" / "experiment").mkdir()
    (tmp_path / "rhmpc" / "experiment" / "b.py").write_text("import rhmpc.sim.loop.c\n")
    (tmp_path / "sim" / "loop" / "c.py").write_text("x = 1\n")
    graph = import_graph(tmp_path)
    assert cycles(graph) == []
    assert cycles(parts_graph(graph)) == [["rhmpc.experiment", "rhmpc.sim.loop"]]
