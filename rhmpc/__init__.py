"""rhmpc: receding-horizon MPC for robot-assisted beating-heart surgery.

The package's parts (``docs/design/index.md`` maps what each may import):

- :mod:`rhmpc.io` — the one guarded reader, the one atomic writer, the table of bounds;
- :mod:`rhmpc.robots`, :mod:`rhmpc.predictors` — the robots, the heart-motion predictors;
- :mod:`rhmpc.sim` — the simulated world: heart, sensors, plant, recordings, closed loop;
- :mod:`rhmpc.positions` — what the controller and the world share: points in the workspace;
- :mod:`rhmpc.control` — the controller: its formulation and settings, its library's binding;
- :mod:`rhmpc.experiment` — one run's configuration (TOML) and its assembly;
- :mod:`rhmpc.timing` — the gain tick every timing is stated in, the host's stalls;
- :mod:`rhmpc.report` — one run's summary, figures, 3-D replay and MAT file;
- :mod:`rhmpc.bench` — the MPC's tick against the gain tick and an exact solve;
- :mod:`rhmpc.openloop` — the predictors open loop: on recordings, in synthetic studies;
- :mod:`rhmpc.tuning` — resumable parameter sweeps;
- :mod:`rhmpc.compare` — predictors × scenarios or recordings in closed loop, the table;
- :mod:`rhmpc.paper` — Tuna et al.'s Tables I–III beside ours, and its findings;
- :mod:`rhmpc.runtime` — the deployment in real time (``rhmpc sil``);
- :mod:`rhmpc.cli` — the ``rhmpc`` console script.

``rhmpc.robots``, ``rhmpc.predictors`` and ``rhmpc.sim`` keep their folders at the repository's
root (``robots/``, ``predictors/``, ``sim/``), installed here by ``package-dir`` in
``pyproject.toml``; imported from a source checkout, they come from that checkout's folders
(``_CheckoutFinder`` below).

The most used names are importable from here (``from rhmpc import RecedingHorizonMPC``); they
load on first use.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from importlib.machinery import ModuleSpec
from pathlib import Path
from typing import Any

_EXPORTS = {
    "Controller": "rhmpc.control.controller",
    "MPCSettings": "rhmpc.control.settings",
    "RecedingHorizonMPC": "rhmpc.control.mpc",
    "ExactReference": "rhmpc.sim.loop.exact",
    "PredictedReference": "rhmpc.control.reference",
    "RunConfig": "rhmpc.experiment",
    "load_config": "rhmpc.experiment",
    "run_experiment": "rhmpc.experiment",
}

__all__ = ["__version__", *sorted(_EXPORTS)]

#: The repository's root, when this package is imported from a source checkout.
_ROOT = Path(__file__).resolve().parent.parent
#: The subpackages whose folders are at the repository's root (pyproject.toml's package-dir).
_ROOT_FOLDERS = {f"{__name__}.{name}": _ROOT / name for name in ("robots", "predictors", "sim")}


class _CheckoutFinder:
    """Finds ``rhmpc.robots``, ``rhmpc.predictors`` and ``rhmpc.sim`` in the folders of the
    source checkout this package is imported from (their subpackages follow from each one's
    ``__path__``).

    A wheel holds those folders inside ``rhmpc/``, and an editable install's finder maps them to
    its checkout; but Python started at a checkout's root (``python``, ``python -m pytest``,
    Sphinx with the root on ``sys.path``) imports ``rhmpc`` from ``./rhmpc``, whose folder
    holds none of the three, whatever is installed: a wheel, an editable install of another
    checkout, or nothing. Installed first on ``sys.meta_path``, and only where this package
    lies in a checkout (``pyproject.toml`` and the three folders beside it; never in an
    installed copy), this finder makes the three the checkout's own, as ``rhmpc`` is.
    """

    @staticmethod
    def find_spec(fullname: str, path: Any = None, target: Any = None) -> ModuleSpec | None:
        folder = _ROOT_FOLDERS.get(fullname)
        if folder is None:
            return None
        return importlib.util.spec_from_file_location(
            fullname, folder / "__init__.py", submodule_search_locations=[str(folder)])


if (_ROOT / "pyproject.toml").is_file() and all(
        (folder / "__init__.py").is_file() for folder in _ROOT_FOLDERS.values()) and not any(
        getattr(finder, "__name__", None) == _CheckoutFinder.__name__ for finder in sys.meta_path):
    sys.meta_path.insert(0, _CheckoutFinder)


def _version() -> str:
    """The installed distribution's version (read when first asked: importlib.metadata costs
    tens of milliseconds of every command's start-up)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("rhmpc")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "0.0.0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        globals()["__version__"] = value = _version()
        return value
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
