"""The compiled hot path of :class:`~.binding.CController`: the ``_rhmpc_step`` CPython extension.

``rhmpc_step.c`` is compiled once per source, Python and NumPy version with the system's C
compiler (the toolchain that builds the exported controllers) against Python's and NumPy's
headers, into the build cache (:func:`~.build.cache_root`), and imported from there. Where that
is impossible (no compiler, no ``Python.h``, a failed build), :func:`load` says why in one line
and the binding keeps its ctypes path.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path
from types import ModuleType

import numpy as np

from .build import COMPILERS, cache_root

SOURCE = Path(__file__).with_name("rhmpc_step.c")
MODULE = "_rhmpc_step"
_FLAGS = ("-O2", "-shared", "-fPIC", "-fno-strict-aliasing")


def _compiler() -> str | None:
    cc = os.environ.get("CC")
    if cc and shutil.which(cc):
        return shutil.which(cc)
    return next((shutil.which(c) for c in COMPILERS if shutil.which(c)), None)


def _command(cc: str, out: Path) -> list[str]:
    include = sysconfig.get_paths()["include"]
    darwin = ["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []
    return [cc, *_FLAGS, *darwin, "-I", include, "-I", np.get_include(), str(SOURCE), "-o",
            str(out)]


def _target(cc: str) -> Path:
    """The module's path in the cache: keyed by its source, the compiler and the ABI."""
    key = hashlib.sha256(SOURCE.read_bytes())
    key.update(" ".join([cc, *_FLAGS, sys.version, np.__version__]).encode())
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return cache_root() / "binding" / f"{MODULE}-{key.hexdigest()[:16]}{suffix}"


def _build(cc: str, target: Path) -> None:
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        built = Path(tmp) / target.name
        proc = subprocess.run(_command(cc, built), capture_output=True, text=True, check=False,
                              timeout=300)
        if proc.returncode != 0:
            lines = (proc.stderr.strip() or proc.stdout.strip()).splitlines() or ["?"]
            first = next((ln for ln in lines if "error" in ln), lines[-1])
            raise OSError(f"compiling {SOURCE.name} failed: {first.strip()}")
        os.replace(built, target)  # atomic: a concurrent build of the same key wins or loses


def _import(path: Path) -> ModuleType:
    loader = importlib.machinery.ExtensionFileLoader(MODULE, str(path))
    spec = importlib.util.spec_from_file_location(MODULE, path, loader=loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


@functools.cache
def load() -> tuple[ModuleType | None, str | None]:
    """(the extension module, None), built at the first call; or (None, one-line reason)."""
    cc = _compiler()
    if cc is None:
        return None, "no C compiler (cc, gcc or clang; or $CC) for the compiled binding"
    include = Path(sysconfig.get_paths()["include"])
    if not (include / "Python.h").is_file():
        return None, f"Python's headers (Python.h) are not in {include}"
    target = _target(cc)
    try:
        if not target.is_file():
            _build(cc, target)
        return _import(target), None
    except (OSError, ImportError, subprocess.SubprocessError) as exc:
        return None, str(exc).splitlines()[0] if str(exc) else type(exc).__name__
