"""The controller as generated C: ``rhmpc export`` and the binding that runs it in a loop.

=============  ==================================================================
``generate``   :func:`export_controller`: the whole real-time controller as C sources
``dynamics``   the controller's model (cancellation, output offset) as CasADi expressions
``binding``    :class:`CController`: the exported controller behind the Python calls
=============  ==================================================================
"""

from __future__ import annotations

from .binding import CController, ToolchainError, build_library, controller_in_c, missing_toolchain
from .generate import PREDICTORS, ExportError, ExportInfo, export_controller

__all__ = [
    "PREDICTORS", "CController", "ExportError", "ExportInfo", "ToolchainError", "build_library",
    "controller_in_c", "export_controller", "missing_toolchain",
]
