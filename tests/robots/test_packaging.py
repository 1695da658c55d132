"""One import package, rhmpc: every subpackage is listed and ships, the URDF and the other
package data ship, all of it found after a non-editable install, not only in-tree.

``robots/``, ``predictors/`` and ``sim/`` stay at the repository's root and install as
``rhmpc.robots``, ``rhmpc.predictors`` and ``rhmpc.sim`` (pyproject.toml's ``package-dir``)."""

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
#: The folders of the installed packages and the package each is installed as.
FOLDERS = {"rhmpc": "rhmpc", "robots": "rhmpc.robots", "predictors": "rhmpc.predictors",
           "sim": "rhmpc.sim"}


def setuptools_table() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]


def installed_as(folder: Path) -> str:
    """The package a folder of the repository is installed as (``sim/heart``: rhmpc.sim.heart)."""
    top, *rest = folder.relative_to(REPO).parts
    return ".".join([FOLDERS[top], *rest])


def test_the_folders_are_mapped_into_rhmpc() -> None:
    table = setuptools_table()
    assert table["package-dir"] == {v: k for k, v in FOLDERS.items() if k != v}
    assert all(p == "rhmpc" or p.startswith("rhmpc.") for p in table["packages"])


def test_every_package_folder_is_installed() -> None:
    """A folder holding an ``__init__.py`` under the installed trees is in the package list
    (a new subpackage cannot be forgotten), and every package-data key is a listed package."""
    listed = set(setuptools_table()["packages"])
    folders = {installed_as(init.parent) for top in FOLDERS
               for init in (REPO / top).rglob("__init__.py") if "__pycache__" not in init.parts}
    assert folders - listed == set(), "add these to [tool.setuptools] packages in pyproject.toml"
    assert set(setuptools_table()["package-data"]) <= listed
    for package in listed:  # and each listed package is a folder of the repository
        top, mapped = max(((f, p) for f, p in FOLDERS.items()
                           if package == p or package.startswith(p + ".")),
                          key=lambda fp: len(fp[1]))
        assert REPO.joinpath(top, *package.removeprefix(mapped).split(".")[1:]).is_dir(), package


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
    # one import package: nothing beside rhmpc/ and its .dist-info
    assert {n.split("/")[0] for n in names} == {"rhmpc", next(
        n.split("/")[0] for n in names if n.endswith(".dist-info/METADATA"))}
    assert {"rhmpc/robots/urdf/phantom_premium_1_5a.urdf", "rhmpc/robots/urdf/phantom.toml"} \
        <= names
    physionet = {f"rhmpc/sim/heart/physionet/{f}" for f in (
        "README.md", "mitdb-100/100.hea", "mitdb-100/100.atr", "1003/1003.hea", "1003/1003.atr")}
    assert physionet <= names
    # every module of the packages' folders ships, subpackages included, under rhmpc/
    sources = {"/".join([*installed_as(p.parent).split("."), p.name])
               for top in FOLDERS for p in (REPO / top).rglob("*.py")}
    assert sources - names == set()
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target),
         str(wheel)],
        check=True, capture_output=True, cwd=tmp_path,
    )
    # Run from a directory without the source tree, importing the installed copy only.
    code = (
        "import sys; import rhmpc.robots as robots; from rhmpc.robots import load_robot; "
        "r = load_robot('phantom'); "
        "assert robots.__file__.startswith(sys.argv[1]), robots.__file__; "
        # an installed copy is no checkout: no finder of the checkout's folders
        "assert '_CheckoutFinder' not in [getattr(f, '__name__', '') for f in sys.meta_path]; "
        "print(r.model.nq)"
    )
    out = subprocess.run(
        [sys.executable, "-I", "-c", f"import sys; sys.path.insert(0, {str(target)!r}); " + code,
         str(target)],
        check=True, capture_output=True, text=True, cwd=tmp_path,
    )
    assert out.stdout.strip() == "3"
    # The shipped PhysioNet records resolve by name inside the installed copy, byte for byte.
    code = (
        "import sys; from rhmpc.sim.heart.rr import find_record, rr_from_annotations; "
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
    # Python started at the checkout's root, the wheel installed: the checkout's own packages.
    assert checkout_imports(target) == [str(REPO / f / "__init__.py") for f in CHECKED]


#: The packages imported from a checkout in the tests below, and the folder each comes from.
CHECKED = ("predictors", "robots", "sim", "predictors/learned", "sim/heart")
#: Python started at the checkout's root (its root first on sys.path), without the editable
#: install's finder: which files the packages of ``CHECKED`` are imported from.
CHECKOUT_IMPORTS = (
    "import sys; sys.meta_path[:] = [f for f in sys.meta_path "
    "if 'Editable' not in getattr(f, '__name__', '')]; sys.path[:0] = sys.argv[1:]; "
    "import importlib; print(*[importlib.import_module(m).__file__ for m in ("
    + ", ".join(f"'rhmpc.{f.replace('/', '.')}'" for f in CHECKED) + ")])"
)


def checkout_imports(*paths: Path) -> list[str]:
    out = subprocess.run(
        [sys.executable, "-I", "-c", CHECKOUT_IMPORTS, str(REPO), *map(str, paths)],
        check=True, capture_output=True, text=True, cwd=REPO)
    return out.stdout.split()


@pytest.mark.slow
def test_a_checkout_imports_its_own_root_folders() -> None:
    """``rhmpc`` imported from the checkout (Python started at its root, without an editable
    install) finds rhmpc.robots, rhmpc.predictors and rhmpc.sim in the checkout's folders."""
    assert checkout_imports() == [str(REPO / f / "__init__.py") for f in CHECKED]
