"""C sources compiled at first use: the simulation's accelerators.

The compiled plant (``sim/plant/chain.c``) and the compiled refresh (``rhmpc/control/refresh.c``)
are plain C99 files compiled with the system's C compiler into a shared library the first time
they are needed, kept in a cache directory and loaded with :mod:`ctypes`. The library's name
holds a hash of the source, the flags and the processor, so a changed source or another
processor (a cache directory shared between machines) gets its own build.

Flags: ``-O3 -march=native`` — the processor's vector instructions, measured 5 % faster on the
plant's 6 × 6 spatial algebra — with ``-ffp-contract=off``: no fused multiply-add, so that each
product is rounded as the source writes it and the results are the same to the bit with or
without ``-march=native`` (a compiler that does not take it builds without it). No fast-math: the
order of every sum is the source's.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

__all__ = ["FLAGS", "build", "cache_dir", "load"]

#: Flags of every build; ``-march=native`` is added where the compiler takes it.
FLAGS = ("-O3", "-shared", "-fPIC", "-std=c99", "-ffp-contract=off")
_TUNED = ("-march=native",)


def cache_dir() -> Path:
    """Where the compiled libraries are kept: ``$RHMPC_CACHE`` or ``~/.cache/rhmpc``."""
    return Path(os.environ.get("RHMPC_CACHE") or Path.home() / ".cache" / "rhmpc")


def _processor() -> str:
    """The processor's model and instruction-set features (Linux), else its platform name."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        lines = []
    wanted = ("model name", "flags", "features", "cpu part", "isa")
    found = {ln.split(":")[0].strip().lower(): ln for ln in lines if ":" in ln}
    return "|".join([platform.machine(), *(found.get(k, "") for k in wanted)]) \
        or platform.processor()


def build(source: Path, stem: str) -> tuple[Path | None, str | None]:
    """The shared library of ``source``, compiled now if the cache does not hold it yet.

    Returns ``(path, None)``, or ``(None, reason)`` where it cannot be built (no compiler,
    a compilation error). Concurrent first uses are safe: each builds in a directory of its
    own and moves the library into place atomically.
    """
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        return None, "no C compiler (cc/gcc) on PATH"
    key = hashlib.sha256(source.read_bytes())
    key.update(" ".join((*FLAGS, *_TUNED, _processor())).encode())
    target = cache_dir() / f"{stem}-{key.hexdigest()[:16]}.so"
    if target.exists():
        return target, None
    error = None
    for flags in ((*FLAGS, *_TUNED), FLAGS):
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
                built = Path(tmp) / target.name
                subprocess.run([compiler, *flags, "-o", str(built), str(source), "-lm"],
                               check=True, capture_output=True, timeout=120)
                os.replace(built, target)  # atomic: concurrent runs see all or nothing
            return target, None
        except (OSError, subprocess.SubprocessError) as exc:
            detail = (getattr(exc, "stderr", b"") or b"").decode(errors="replace")[:200]
            error = f"compiling {source.name} failed: {exc} {detail}".strip()
    return None, error


def load(source: Path, stem: str, kind: type[ctypes.CDLL] = ctypes.CDLL
         ) -> tuple[ctypes.CDLL | None, str | None]:
    """:func:`build` ``source`` and load it as ``kind`` (:class:`ctypes.CDLL`, or
    :class:`ctypes.PyDLL` to keep the GIL in its calls): ``(library, None)`` or
    ``(None, reason)``."""
    target, reason = build(source, stem)
    if target is None:
        return None, reason
    try:
        return kind(str(target)), None
    except OSError as exc:
        return None, f"loading {target.name} failed: {exc}"
