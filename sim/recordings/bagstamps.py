"""A bag topic's sample times: its messages' header stamps, not the bag's receive times.

A bag stores each message with the time the recorder received it; a stamped message also
carries the time its measurement was taken, in its header. The receive time adds the latency
from the tracker to the recorder (its processing, the network, the middleware's queues) and that
latency's jitter, so the stamps are the sample times (``docs/design/decisions/bag-stamps.md``).
Where the two disagree:

- a lag, receive time − stamp, of any size, constant or jittered: the stamps are used as they
  are, and ``rhmpc data show`` reports the lag;
- messages received out of their stamps' order (queued or published late): put in stamp order,
  counted, and warned about;
- a stamp repeated (a message sent twice): the first message received is kept, the others are
  counted, warned about and left out;
- stamps left unset (zero) by a publisher: in every message, the receive times are the sample
  times and a warning says so; in some, those messages are left out with a warning.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Stamps:
    """The sample times of a topic's messages.

    Attributes
    ----------
    source : str
        ``"header"`` (the stamps) or ``"receive"`` (no message had its stamp set).
    order : ndarray of int
        The messages kept (indices in the order they were received), in time order.
    t : ndarray
        Their times from the first one kept [s].
    start_ns : int
        The first time kept, since the epoch [ns].
    unset : int
        Messages left out for an unset stamp among set ones.
    out_of_order : int
        Messages received after one stamped later.
    repeated : int
        Messages left out for a stamp an earlier one had.
    lag : ndarray
        Receive time − stamp of each message kept [s] (zeros when ``source`` is ``receive``).
    """

    source: str
    order: np.ndarray
    t: np.ndarray
    start_ns: int
    unset: int
    out_of_order: int
    repeated: int
    lag: np.ndarray


def sample_times(stamp_ns: np.ndarray, receive_ns: np.ndarray) -> Stamps:
    """The sample times of messages with header stamps ``stamp_ns`` and receive times
    ``receive_ns`` [ns since the epoch], both in the order received (module docstring)."""
    stamp = np.asarray(stamp_ns, dtype=np.int64)
    receive = np.asarray(receive_ns, dtype=np.int64)
    source = "header"
    if stamp.size and not stamp.any():
        stamp, source = receive, "receive"
    index = np.flatnonzero(stamp != 0)
    kept = stamp[index]
    later = kept[1:] < np.maximum.accumulate(kept)[:-1]
    order = index[np.argsort(kept, kind="stable")]
    first = np.ones(order.size, dtype=bool)
    first[1:] = np.diff(stamp[order]) != 0
    order = order[first]
    start = int(stamp[order[0]]) if order.size else 0
    return Stamps(source, order, (stamp[order] - start) * 1e-9, start, stamp.size - index.size,
                  int(np.sum(later)), int(np.sum(~first)), (receive[order] - stamp[order]) * 1e-9)


def stamp_problems(stamps: Stamps, where: str) -> list[str]:
    """What a run is warned about: receive times used, messages reordered or left out."""
    out = []
    if stamps.source == "receive":
        out.append(f"{where}: no message has its header stamp set: the times are when the "
                   "bag received them, which add the transport's latency and jitter")
    if stamps.unset:
        out.append(f"{where}: {stamps.unset} message(s) without a header stamp (zero) left out")
    if stamps.out_of_order:
        out.append(f"{where}: {stamps.out_of_order} message(s) received out of their stamps' "
                   "order, put in stamp order")
    if stamps.repeated:
        out.append(f"{where}: {stamps.repeated} message(s) repeat an earlier one's stamp, left "
                   "out")
    return out
