"""C sources compiled at first use (sim.compiled): cached per source, flags and processor; a
compiler without ``-march=native`` still builds; no compiler is a reason, not a crash."""

from __future__ import annotations

import ctypes
import shutil
import stat

import pytest

from sim import compiled

SOURCE = "double twice(double x) { return 2.0 * x; }\n"
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                              reason="no C compiler (cc/gcc) on PATH")


@pytest.fixture
def source(tmp_path, monkeypatch):
    monkeypatch.setenv("RHMPC_CACHE", str(tmp_path / "cache"))
    path = tmp_path / "twice.c"
    path.write_text(SOURCE)
    return path


@needs_cc
def test_a_source_is_built_once_and_loaded(source):
    target, reason = compiled.build(source, "twice")
    assert reason is None and target.parent == compiled.cache_dir()
    library = ctypes.CDLL(str(target))
    library.twice.argtypes, library.twice.restype = [ctypes.c_double], ctypes.c_double
    assert library.twice(1.25) == 2.5
    mtime = target.stat().st_mtime_ns
    assert compiled.build(source, "twice") == (target, None)  # from the cache
    assert target.stat().st_mtime_ns == mtime
    source.write_text(SOURCE.replace("2.0", "3.0"))
    other, _ = compiled.build(source, "twice")
    assert other != target and other.exists()  # a changed source is a new library


@needs_cc
def test_a_compiler_without_march_native_builds_without_it(source, tmp_path, monkeypatch):
    real = shutil.which("cc") or shutil.which("gcc")
    fake = tmp_path / "cc"
    fake.write_text(f'#!/bin/sh\nfor a in "$@"; do [ "$a" = -march=native ] && exit 1; done\n'
                    f'exec {real} "$@"\n')
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("CC", str(fake))
    target, reason = compiled.build(source, "twice")
    assert reason is None and target.exists()


def test_no_compiler_is_a_reason(source, tmp_path, monkeypatch):
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    target, reason = compiled.build(source, "twice")
    assert target is None and reason.startswith("compiling twice.c failed")
    monkeypatch.delenv("CC")
    monkeypatch.setattr(compiled.shutil, "which", lambda name: None)
    assert compiled.build(source, "twice") == (None, "no C compiler (cc/gcc) on PATH")
