"""The controller as generated C: export, build, and a binding (see :mod:`.generate`)."""

from __future__ import annotations

from .binding import CController
from .build import (
    ToolchainError,
    build_cached,
    build_library,
    cache_root,
    missing_toolchain,
)
from .generate import ExportError, ExportInfo, export_controller, export_key, extra_source

__all__ = [
    "CController",
    "ExportError",
    "ExportInfo",
    "ToolchainError",
    "build_cached",
    "build_library",
    "cache_root",
    "compiled_controller",
    "export_controller",
    "export_key",
    "extra_source",
    "missing_toolchain",
]


def compiled_controller(mpc, robot: str, cache: str | None = None) -> CController:
    """The compiled twin of ``mpc`` (exported and built once per distinct data, then cached)."""
    lib = build_cached(mpc, robot, cache)
    extra = mpc.offset if extra_source(mpc) == "caller" else None  # else computed in C
    controller = CController(lib, dims=(mpc.N, mpc.nx, mpc.nu, mpc.ny), extra_inputs=extra)
    controller.twin = mpc  # the Python controller it was generated from (its gain tick, its QP)
    return controller
