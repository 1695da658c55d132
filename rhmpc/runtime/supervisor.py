"""The supervision of a deployment's parts: started together, watched, stopped in the safe
state together, and the one line that names a failed part and its cause.

The controller is stopped first: its silence brings the robot's drivers to their safe state
after their watchdog (:data:`rhmpc.runtime.processes.WATCHDOG_TICKS`), then every other part.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from rhmpc import io
from rhmpc.runtime import processes
from rhmpc.tuning.workers import program_dies_with_parent

__all__ = ["GRACE_S", "Group", "Part", "cause", "supervise"]

#: Seconds from a stop request to SIGKILL.
GRACE_S = 2.0
#: What the controller program's exit statuses mean.
_CONTROLLER_EXITS = {1: "was stopped by a signal", 2: "refused its command line"}


@dataclass
class Part:
    """A child process of the run and the part it plays."""

    name: str
    child: subprocess.Popen | multiprocessing.Process

    @property
    def code(self) -> int | None:
        """Its exit status (negative: the signal that ended it), None while it runs."""
        if isinstance(self.child, subprocess.Popen):
            return self.child.poll()
        return None if self.child.is_alive() else self.child.exitcode

    def stop(self) -> None:
        if self.code is None:
            self.child.terminate()

    def kill(self) -> None:
        if self.code is None:
            self.child.kill()

    def reap(self) -> None:
        if isinstance(self.child, subprocess.Popen):
            self.child.wait()
        else:
            self.child.join()


class Group:
    """The run's parts: started, supervised and stopped together, the controller first."""

    def __init__(self) -> None:
        self.parts: list[Part] = []

    def spawn(self, name: str, command: list[str], fds: tuple[int, ...] = ()) -> None:
        child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                 text=True, pass_fds=fds, preexec_fn=program_dies_with_parent)
        self.parts.append(Part(name, child))

    def fork(self, name: str, target, *args) -> None:
        child = multiprocessing.get_context("fork").Process(
            target=processes.run_part, args=(name, target, *args, os.getpid()), name=name)
        child.start()
        self.parts.append(Part(name, child))

    def failed(self) -> Part | None:
        """The first part that ended with a failure (the host probe's own is not one)."""
        return next((p for p in self.parts if p.name != "host probe" and p.code not in (None, 0)),
                    None)

    def running(self) -> bool:
        return any(p.code is None for p in self.parts)

    def stop(self) -> None:
        """The controller first (its silence brings the robot's drivers to their safe state
        after their watchdog), the others once they braked; SIGKILL after :data:`GRACE_S`."""
        for part in self.parts:
            if part.name == "controller":
                part.stop()
        time.sleep(2 * processes.WATCHDOG_TICKS * 0.5e-3)
        for part in self.parts:
            part.stop()
        deadline = time.monotonic() + GRACE_S
        while self.running() and time.monotonic() < deadline:
            time.sleep(0.02)
        for part in self.parts:
            part.kill()
            part.reap()


def supervise(group: Group, seconds: float) -> Part | None:
    """Watch the parts until every one has ended (None) or one failed or hung (that part)."""
    deadline = time.monotonic() + seconds
    while group.running():
        failed = group.failed()
        if failed is not None:
            return failed
        if time.monotonic() > deadline:
            return next(p for p in group.parts if p.code is None)
        time.sleep(0.05)
    return group.failed()


def cause(part: Part, role: processes.Role, folder: Path, duration: float) -> str:
    """One line: which part, what happened, when."""
    at = max(0.0, (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - role.epoch_ns) * 1e-9)
    code = part.code
    if code is None:
        what = "hung (still running after the run's end)"
    elif code < 0:
        what = f"died ({signal.Signals(-code).name})"
    elif part.name == "controller" and code == 3:
        doc = io.read_json(folder / "controller.json", track=False)
        what = f"stopped the run: {doc.get('stopped', 'its supervisor')}"
    elif part.name == "controller":
        err = part.child.stderr.read().strip().splitlines() if part.child.stderr else []
        what = f"{_CONTROLLER_EXITS.get(code, f'failed (exit {code})')}" + \
            (f": {err[-1]}" if err else "")
    else:
        fault = folder / f"{part.name}.fault"
        what = "failed: " + (io.read_text(fault).strip() if fault.is_file() else f"exit {code}")
    return (f"the {part.name} {what} at {min(at, duration):.1f} s of the {duration:g}-s run; "
            "every part stopped in the safe state")
