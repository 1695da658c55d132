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

from rhmpc.experiment.assembly import Run, build_run, build_stream, make_sensor
from rhmpc.experiment.config import (
    GROUND_TRUTHS,
    SECTIONS,
    RunConfig,
    load_config,
    read_toml,
    run_config,
    save_config,
)
from rhmpc.experiment.run import run_experiment, versions

__all__ = [
    "GROUND_TRUTHS", "SECTIONS", "Run", "RunConfig", "build_run", "build_stream", "load_config",
    "make_sensor", "read_toml", "run_config", "run_experiment", "save_config", "versions",
]
