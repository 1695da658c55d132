"""The run's status on ROS 2: ``diagnostic_msgs/DiagnosticStatus`` on ``/rhmpc/status``.

Each bridge publishes, once a second and whenever its state changes, one status named after
it (``rhmpc sil: tracker bridge``, ``rhmpc sil: console bridge``) as ROS 2's diagnostics do:

- ``OK`` *waiting for the run's start* before the run's instant 0, *running* during the run,
  *ended* after it;
- ``WARN`` with the bridge's own reason during the run (no sample for longer than a receiver
  takes one, readings that come too late);
- ``ERROR`` *stopped before the run's end* when the deployment stops it early (its supervisor
  or Ctrl-C; ``rhmpc sil`` names the part and the cause).

Its values are the run's instant 0 in ROS time (``epoch``, ``SEC.NANOSEC``: a tracker that
replays a recording starts from it), the run's clock and length [s], and the bridge's counts.
"""

from __future__ import annotations

from rhmpc.runtime.ros2.messages import DiagnosticStatus, KeyValue
from rhmpc.runtime.ros2.names import NAMESPACE, RosClock

__all__ = ["PERIOD", "TOPIC", "Status"]

#: Where the status is published.
TOPIC = f"{NAMESPACE}/status"
#: Seconds between two statuses of an unchanged state.
PERIOD = 1.0


class Status:
    """One bridge's status publisher.

    Parameters
    ----------
    node : Node
        The bridge's node (:class:`~rhmpc.runtime.ros2.dds.Node`).
    part : str
        The bridge, as its status names it.
    clock : RosClock
        The run's clock against ROS time.
    duration : float
        The run's length [s].
    """

    def __init__(self, node, part: str, clock: RosClock, duration: float) -> None:
        self.writer = node.publisher(TOPIC, DiagnosticStatus)
        self.name, self.clock, self.duration = f"rhmpc sil: {part}", clock, duration
        self.last: tuple[int, str] | None = None
        self.sent_at = -float("inf")

    def update(self, values: dict, warning: str | None = None) -> None:
        """Publish the state at the run's clock now if it changed or :data:`PERIOD` passed."""
        now = self.clock.now()
        if now < 0:
            state = (DiagnosticStatus.OK, "waiting for the run's start")
        elif now <= self.duration:
            state = (DiagnosticStatus.WARN, warning) if warning else (DiagnosticStatus.OK,
                                                                      "running")
        else:
            state = (DiagnosticStatus.OK, "ended")
        if state != self.last or now - self.sent_at >= PERIOD:
            self._publish(state, values, now)

    def end(self, early: bool, values: dict) -> None:
        """The last status: ended, or stopped before the run's end."""
        state = (DiagnosticStatus.ERROR, "stopped before the run's end in the safe state "
                 "(rhmpc sil names the part and the cause)") if early else \
            (DiagnosticStatus.OK, "ended")
        self._publish(state, values, self.clock.now())

    def _publish(self, state: tuple[int, str], values: dict, now: float) -> None:
        sec, nanosec = divmod(self.clock.epoch_ros_ns(), 1_000_000_000)
        pairs = {"epoch": f"{sec}.{nanosec:09d}", "run_clock_s": f"{now:.3f}",
                 "duration_s": f"{self.duration:g}", **values}
        self.writer.write(DiagnosticStatus(state[0], self.name, state[1], "",
                                           [KeyValue(k, str(v)) for k, v in pairs.items()]))
        self.last, self.sent_at = state, now
