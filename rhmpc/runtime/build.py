"""The controller process: the exported controller and its transport (``export/``), built with
CMake.

The controller a run deploys is :func:`rhmpc.experiment.assembly.deployable` of its settings,
exported by :func:`rhmpc.control.export.export_controller`. Its own predictor, which serves
when the forecasts from the predictor process stop, is the run's predictor if the export runs
it (the one-step or the generalized RLS), else the generalized RLS. The build is kept in the
cache (``$RHMPC_CACHE/sil/<key>``, the key a hash of the export and of the program's sources),
so that a second run of the same settings starts at once.
"""

from __future__ import annotations

import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path

from rhmpc import io
from rhmpc.compiled import cache_dir, compiler
from rhmpc.control.export import PREDICTORS, export_controller
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig
from rhmpc.experiment.assembly import deployable
from rhmpc.tuning.workers import program_dies_with_parent

__all__ = ["SOURCES", "TRANSPORT", "BuiltController", "build_controller", "internal_predictor",
           "missing_toolchain", "write_transport"]

#: The transport's files (package data of :mod:`rhmpc.runtime`, folder ``export``), which
#: ``rhmpc export`` writes beside the controller (``DIR/udp``, :func:`write_transport`).
SOURCES = ("controller.c", "robot_client.c", "rhmpc_wire.h", "CMakeLists.txt")
#: The folder of an export the transport goes to.
TRANSPORT = "udp"
#: The longest a configure or a build may take [s].
BUILD_TIMEOUT = 600


@dataclass(frozen=True)
class BuiltController:
    """The controller's program, the robot-side client built beside it, and what they were
    built from."""

    program: Path
    controller: object  # the Python controller it was exported from
    internal: str  # the predictor the controller runs itself

    @property
    def client(self) -> Path:
        """The robot-side client (``robot_client.c``) for the same export."""
        return self.program.parent / "rhmpc_robot_client"


def internal_predictor(config: RunConfig) -> str:
    """The predictor the exported controller runs itself: the run's if it exports, else the
    generalized RLS."""
    return config.predictor if config.predictor in PREDICTORS else "generalized"


@functools.cache
def missing_toolchain() -> str | None:
    """None if this host builds the deployment's programs (cmake, a C compiler, OpenSSL's
    libcrypto and its headers), else what is missing, on one line."""
    cc = compiler()
    if shutil.which("cmake") is None or cc is None:
        return "the deployment's programs need cmake and a C compiler"
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / "probe.c"
        source.write_text("#include <openssl/evp.h>\nint main(void) { return EVP_MAC_fetch(0, "
                          "\"HMAC\", 0) == 0; }\n")
        done = subprocess.run([cc, str(source), "-o", str(Path(tmp) / "probe"), "-lcrypto"],
                              capture_output=True)
    if done.returncode != 0:
        return ("the deployment's programs need OpenSSL's libcrypto and its headers "
                "(Debian: apt-get install libssl-dev)")
    return None


def _cmake(*args: str) -> None:
    cmake = shutil.which("cmake")
    if cmake is None:
        raise UsageError("rhmpc sil builds the controller with CMake: cmake is not on the PATH")
    done = subprocess.run([cmake, *args], capture_output=True, text=True, timeout=BUILD_TIMEOUT,
                          preexec_fn=program_dies_with_parent)
    if done.returncode != 0:
        text = done.stderr.strip() or done.stdout.strip()
        if "OpenSSL" in text and args[0] == "-S":
            raise UsageError("the deployment's programs need OpenSSL's libcrypto and its "
                             "headers (Debian: apt-get install libssl-dev)")
        last = text.splitlines()[-1:] or ["no output"]
        raise UsageError(f"the controller's build failed (cmake {args[0]}): {last[0]}")


def build_controller(config: RunConfig, sensor_rate: float) -> BuiltController:
    """Export the controller of ``config`` for a sensor of ``sensor_rate`` [Hz] and build its
    program with CMake (or take the cached build)."""
    internal = internal_predictor(config)
    if internal != config.predictor:  # the run's predictor's settings (a model file …) are not its
        config = config.replace(predictor=internal, predictor_settings={})
    controller = deployable(config, sensor_rate)
    name = controller.mpc.arm.robot.name
    with tempfile.TemporaryDirectory(prefix="rhmpc-sil-") as tmp:
        info = export_controller(controller, Path(tmp) / "export", robot=name)
        key = hashlib.sha256(info.key.encode())
        for source in SOURCES:
            key.update(_source(source))
        target = cache_dir() / "sil" / key.hexdigest()[:16]
        program = target / "build" / "rhmpc_sil_controller"
        if not program.is_file():
            staging = Path(tempfile.mkdtemp(prefix="build-", dir=_folder(target.parent)))
            shutil.copytree(Path(tmp) / "export", staging / "export")
            write_transport(staging / "export")
            _cmake("-S", str(staging / "export" / TRANSPORT), "-B", str(staging / "build"),
                   "-DCMAKE_BUILD_TYPE=Release")
            _cmake("--build", str(staging / "build"), "--target", "rhmpc_sil_controller",
                   "rhmpc_robot_client")
            try:
                os.replace(staging, target)  # whole, or not at all (another run built it first)
            except OSError:
                shutil.rmtree(staging, ignore_errors=True)
    return BuiltController(program, controller, internal)


def _source(name: str) -> bytes:
    """One of the transport's files, as the package holds it."""
    return files(__package__).joinpath("export", name).read_bytes()


def write_transport(outdir: Path) -> list[str]:
    """Write the transport into the export folder ``outdir`` (``udp/``: the controller's
    real-time program over the wire format, a robot-side client, their CMake project), each
    file atomically and inside ``outdir`` (:mod:`rhmpc.io`). Returns the files' names."""
    io.make_folder(outdir / TRANSPORT, root=outdir)
    for source in SOURCES:
        io.write_bytes(outdir / TRANSPORT / source, _source(source), root=outdir)
    return [f"{TRANSPORT}/{source}" for source in SOURCES]


def _folder(path: Path) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    return path
