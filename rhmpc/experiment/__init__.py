"""One closed-loop run, from a :class:`RunConfig` to a JSON-ready result document.

=============  ==================================================================
``config``     :class:`RunConfig`: every setting of a run, its TOML file;
               :func:`run_config`: the one merge of its sources (defaults, file,
               preset, options, ``--set``)
``presets``    the named operating points (``--preset``)
``assembly``   :func:`build_run`: robot, heart motion, sensor stream, reference,
               controller, plant (one function each)
``run``        :func:`run_experiment`: the closed loop and its JSON document
=============  ==================================================================

``rhmpc simulate``, ``rhmpc compare`` and ``rhmpc tune`` all run through
:func:`run_experiment`.
"""

from __future__ import annotations

import importlib

#: Each name of the package and its module: loaded when first asked for, so that the command
#: line's parsers (``rhmpc sil --help``) read the presets without the run's stack.
_EXPORTS = {
    "Run": "assembly", "build_run": "assembly", "build_stream": "assembly",
    "make_sensor": "assembly", "GROUND_TRUTHS": "config", "SECTIONS": "config",
    "RunConfig": "config", "load_config": "config", "read_toml": "config",
    "run_config": "config", "save_config": "config", "run_experiment": "run",
    "versions": "run",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
