"""C sources compiled at first use: the one build helper of every compiled piece.

Two pieces are C: the controller ``rhmpc export`` generates (:mod:`rhmpc.control.export`, run in
a simulation by ``--controller c``) and the plant's dynamics kernel (``sim/plant/chain.c``). Both
are plain C99 compiled with the system's C compiler into a shared library the first time they
are needed, kept in a cache directory (``$RHMPC_CACHE``) and loaded with :mod:`ctypes`. The
library's name holds a hash of the sources, the flags and the processor, so a changed source or
another processor (a cache directory shared between machines) gets its own build.

Flags: ``-O3 -march=native`` (the processor's vector instructions) with ``-ffp-contract=off``: no
fused multiply-add, so that each product is rounded as the source writes it and the results are
the same to the bit with or without ``-march=native`` (a compiler that does not take it builds
without it). No fast-math: the order of every sum is the source's.
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

__all__ = ["FLAGS", "build", "cache_dir", "compiler", "load"]

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


def compiler() -> str | None:
    """The C compiler: ``$CC``, else ``cc`` or ``gcc`` on the PATH (None if there is none)."""
    return os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")


def build(sources: Path | list[Path], stem: str, include: tuple[Path, ...] = ()
          ) -> tuple[Path | None, str | None]:
    """The shared library of the C ``sources``, compiled now if the cache does not hold it yet.

    ``include``: directories of their headers (hashed with the sources). Returns ``(path,
    None)``, or ``(None, reason)`` where it cannot be built (no compiler, a compilation error).
    Concurrent first uses are safe: each builds in a directory of its own and moves the library
    into place atomically.
    """
    cc = compiler()
    if cc is None:
        return None, "no C compiler (cc/gcc) on PATH"
    sources = [sources] if isinstance(sources, Path) else sorted(sources)
    key = hashlib.sha256(" ".join((*FLAGS, *_TUNED, _processor())).encode())
    headers = sorted(h for d in include for h in Path(d).rglob("*.h"))
    for path in (*sources, *headers):
        key.update(path.name.encode() + path.read_bytes())
    target = cache_dir() / f"{stem}-{key.hexdigest()[:16]}.so"
    if target.exists():
        return target, None
    error = None
    for flags in ((*FLAGS, *_TUNED), FLAGS):
        try:
            target.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
                built = Path(tmp) / target.name
                subprocess.run([cc, *flags, *(f"-I{d}" for d in include), "-o", str(built),
                                *map(str, sources), "-lm"],
                               check=True, capture_output=True, timeout=300)
                os.replace(built, target)  # atomic: concurrent runs see all or nothing
            return target, None
        except (OSError, subprocess.SubprocessError) as exc:
            detail = (getattr(exc, "stderr", b"") or b"").decode(errors="replace")[:300]
            error = f"compiling {sources[0].name} failed: {exc} {detail}".strip()
    return None, error


def load(sources: Path | list[Path], stem: str, include: tuple[Path, ...] = (),
         kind: type[ctypes.CDLL] = ctypes.CDLL) -> tuple[ctypes.CDLL | None, str | None]:
    """:func:`build` ``sources`` and load the library as ``kind`` (:class:`ctypes.CDLL`, or
    :class:`ctypes.PyDLL` to keep the GIL in its calls): ``(library, None)`` or
    ``(None, reason)``."""
    target, reason = build(sources, stem, include)
    if target is None:
        return None, reason
    try:
        return kind(str(target)), None
    except OSError as exc:
        return None, f"loading {target.name} failed: {exc}"
