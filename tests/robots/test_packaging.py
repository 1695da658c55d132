"""The URDF ships as package data and every subpackage ships: found after a non-editable install,
not only in-tree."""

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_urdf_found_after_non_editable_install(tmp_path):
    wheel_dir, target = tmp_path / "wheel", tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
         "-w", str(wheel_dir), str(REPO)],
        check=True, capture_output=True, cwd=tmp_path,
    )
    (wheel,) = wheel_dir.glob("rhmpc-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"robots/urdf/phantom_premium_1_5a.urdf", "robots/urdf/phantom.toml"} <= names
    physionet = {f"sim/heart/physionet/{f}" for f in (
        "README.md", "mitdb-100/100.hea", "mitdb-100/100.atr", "1003/1003.hea", "1003/1003.atr")}
    assert physionet <= names
    # every module of the five import packages ships, subpackages included
    sources = {p.relative_to(REPO).as_posix() for top in ("rhmpc", "robots", "predictors", "sim",
                                                          "boundary")
               for p in (REPO / top).rglob("*.py")}
    assert sources - names == set()
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
         str(wheel)],
        check=True, capture_output=True, cwd=tmp_path,
    )
    # Run from a directory without the source tree, importing the installed copy only.
    code = (
        "import robots, sys; from robots import load_robot; r = load_robot('phantom'); "
        "assert robots.__file__.startswith(sys.argv[1]), robots.__file__; print(r.model.nq)"
    )
    out = subprocess.run(
        [sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, {str(target)!r}); " + code,
         str(target)],
        check=True, capture_output=True, text=True, cwd=tmp_path,
    )
    assert out.stdout.strip() == "3"
    # The shipped PhysioNet records resolve by name inside the installed copy, byte for byte.
    code = (
        "import sys; from sim.heart.rr import find_record, rr_from_annotations; "
        "b = find_record('mitdb-100'); assert str(b).startswith(sys.argv[1]), b; "
        "print(b.with_suffix('.atr').read_bytes().hex(), rr_from_annotations('1003').size)"
    )
    out = subprocess.run(
        [sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, {str(target)!r}); " + code,
         str(target)],
        check=True, capture_output=True, text=True, cwd=tmp_path,
    )
    atr, beats = out.stdout.split()
    assert bytes.fromhex(atr) == (REPO / "sim/heart/physionet/mitdb-100/100.atr").read_bytes()
    assert int(beats) > 900
