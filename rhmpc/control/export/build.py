"""Build an exported controller with cmake and the system's C compiler.

The build goes to a cache directory keyed by :func:`~.generate.export_key`, so a controller with
the same data is compiled once (``$RHMPC_CACHE_DIR``, default ``~/.cache/rhmpc``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from rhmpc.control.mpc import RecedingHorizonMPC

from .generate import export_controller, export_key

#: C compilers looked for, after ``$CC``.
COMPILERS = ("cc", "gcc", "clang")


class ToolchainError(OSError):
    """No C compiler or no cmake, or the build failed (the message says which, in one line)."""


def missing_toolchain() -> str | None:
    """None if cmake and a C compiler are on the PATH, else a one-line reason."""
    if shutil.which("cmake") is None:
        return "the C controller needs cmake, which is not on the PATH"
    cc = os.environ.get("CC")
    if not (cc and shutil.which(cc)) and not any(shutil.which(c) for c in COMPILERS):
        return "the C controller needs a C compiler (cc, gcc or clang; or $CC), none found"
    return None


def cache_root() -> Path:
    """Where built controllers are kept: ``$RHMPC_CACHE_DIR`` or ``~/.cache/rhmpc``."""
    env = os.environ.get("RHMPC_CACHE_DIR")
    if env:
        return Path(env)
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "rhmpc"


def _run(cmd: list[str], what: str) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        tail = (proc.stderr.strip() or proc.stdout.strip()).splitlines()[-1:] or ["?"]
        raise ToolchainError(f"{what} failed: {tail[0]}")


def shared_library_name() -> str:
    return "librhmpc_shared.dylib" if os.uname().sysname == "Darwin" else "librhmpc_shared.so"


def build_library(srcdir: str | Path, builddir: str | Path) -> Path:
    """``cmake -S srcdir -B builddir && cmake --build builddir``; returns the shared library.

    Raises
    ------
    ToolchainError
        If cmake or a compiler is missing, or the configure/build step fails.
    """
    reason = missing_toolchain()
    if reason:
        raise ToolchainError(reason)
    srcdir, builddir = Path(srcdir), Path(builddir)
    _run(["cmake", "-S", str(srcdir), "-B", str(builddir), "-DCMAKE_BUILD_TYPE=Release"],
         "cmake configure")
    _run(["cmake", "--build", str(builddir), "--parallel", "2"], "cmake build")
    lib = builddir / shared_library_name()
    if not lib.is_file():
        raise ToolchainError(f"the build did not produce {lib}")
    return lib


def build_cached(mpc: RecedingHorizonMPC, robot: str, root: str | Path | None = None) -> Path:
    """Export and build ``mpc`` once per distinct data; returns the shared library's path."""
    root = Path(root) if root is not None else cache_root()
    final = root / "c-export" / export_key(mpc, robot)
    lib = final / "build" / shared_library_name()
    if lib.is_file():
        return lib
    final.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=final.parent) as tmp:
        export_controller(mpc, Path(tmp) / "src", robot=robot)
        build_library(Path(tmp) / "src", Path(tmp) / "build")
        try:
            os.replace(tmp, final)  # atomic: a concurrent build of the same key wins or loses
        except OSError:
            if not lib.is_file():
                raise
        else:
            os.mkdir(tmp)  # TemporaryDirectory removes it
    return lib
