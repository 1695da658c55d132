"""The controller as generated C: ``rhmpc export`` and the binding that runs it.

=============  ==================================================================
``generate``   :func:`export_controller`: the whole real-time controller as C sources
``arrays``     the controller's numbers as C arrays (``rhmpc_data.c``)
``dynamics``   the controller's model (cancellation, output offset) as CasADi expressions
``layout``     the names and the public struct the C and its binding share
``binding``    :class:`Controller`: the library built from an export, behind Python calls
=============  ==================================================================
"""

from __future__ import annotations

from .binding import Controller, ToolchainError, build_library, missing_toolchain
from .generate import PREDICTORS, ExportError, ExportInfo, export_controller

__all__ = [
    "PREDICTORS", "Controller", "ExportError", "ExportInfo", "ToolchainError", "build_library",
    "export_controller", "missing_toolchain",
]
