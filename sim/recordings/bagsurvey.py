"""What a ROS bag holds, topic by topic: ``rhmpc data show BAG``.

Each topic's type and count of messages, its rate and span, and, for a type read
(:mod:`rhmpc.sim.recordings.bagmsgs`), what its header stamps say: the gaps between them
(:mod:`rhmpc.sim.recordings.gaps`), the messages received out of their stamps' order or
repeating a stamp, and the lag from stamp to receive time
(:mod:`rhmpc.sim.recordings.bagstamps`). A topic of transforms gives a row per child frame. A
type not read has its receive times alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.sim.recordings.bagfile import open_bag, samples
from rhmpc.sim.recordings.bagmsgs import TYPES, type_name
from rhmpc.sim.recordings.bagstamps import sample_times
from rhmpc.sim.recordings.gaps import find_gaps
from rhmpc.sim.recordings.recorded import nominal_rate


def survey(path: str | Path) -> dict:
    """The bag's format and a row per topic (per child frame of a topic of transforms), read
    in one pass over its messages (module docstring)."""
    path = Path(path)
    with open_bag(path) as (bag, kind):
        topics = bag.topics
        io.check("samples", sum(info.msgcount for info in topics.values()), str(path))
        seen: dict[tuple[str, str | None], tuple[list, list, list]] = {
            (name, None): ([], [], []) for name in topics}
        connections = [c for info in topics.values() for c in info.connections]
        for topic, receive, items in samples(path, bag, connections):
            for child, stamp, points in items or [(None, 0, [])]:
                stamps, received, width = seen.setdefault((topic, child), ([], [], []))
                stamps.append(stamp)
                received.append(receive)
                width.append(len(points))
    rows = [_row(topic, child, topics[topic].msgtype, *data)
            for (topic, child), data in sorted(seen.items(), key=lambda kv: (kv[0][0],
                                                                             kv[0][1] or ""))
            if data[1] or not _has_frames(seen, topic)]
    return {"bag": str(path), "format": kind, "topics": rows}


def _has_frames(seen: dict, topic: str) -> bool:
    """Whether ``topic`` has rows of its child frames (its own row then is left out)."""
    return any(t == topic and child is not None and data[1] for (t, child), data in seen.items())


def _row(topic: str, frame: str | None, msgtype: str | None, stamps: list, received: list,
         width: list) -> dict:
    """One topic's (or child frame's) row: counts, rate, span; for a type read, its stamps."""
    read = msgtype in TYPES
    times = sample_times(np.array(stamps if read else received, dtype=np.int64),
                         np.array(received, dtype=np.int64))
    t = times.t
    row = {"topic": topic, "frame": frame, "type": type_name(msgtype), "read": read,
           "messages": len(received), "points": max(width) if read and width else None,
           "rate_hz": round(nominal_rate(t), 4) if t.size > 1 and t[-1] > t[0] else None,
           "span_s": round(float(t[-1]), 4) if t.size else None,
           "stamps": times.source if read else "receive"}
    if read and t.size:
        lag = 1e3 * times.lag
        row.update(gaps=find_gaps(t).as_dict(), out_of_order=times.out_of_order,
                   repeated=times.repeated, unset=times.unset,
                   lag_ms={"p50": round(float(np.median(lag)), 3),
                           "min": round(float(lag.min()), 3), "max": round(float(lag.max()), 3)})
    return row


def survey_lines(doc: dict) -> list[str]:
    """:func:`survey`'s document as lines of text: a table of the topics, then what the stamps
    of each topic read say, flagging gaps and stamps out of order."""
    rows = doc["topics"]
    lines = [f"{doc['bag']}: {doc['format']}, {len(rows)} topic(s)",
             f"  {'topic':<28} {'type':<34} {'messages':>8} {'rate':>8} {'span':>8} "
             f"{'points':>6}",
             f"  {'':<28} {'':<34} {'':>8} {'[Hz]':>8} {'[s]':>8}"]
    for r in rows:
        lines.append(f"  {_label(r):<28} {r['type']:<34} {r['messages']:>8} "
                     f"{_num(r['rate_hz']):>8} {_num(r['span_s']):>8} {_num(r['points']):>6}")
    lines += [f"  {_label(r):<28} {_stamp_text(r)}" for r in rows if r["read"] and r["span_s"]
              is not None]
    lines.append("  read a topic with --topic NAME (--poi N: one of several points; --frame "
                 "NAME: a tf topic's)")
    return lines


def _label(row: dict) -> str:
    return row["topic"] + (f" [{row['frame']}]" if row["frame"] else "")


def _num(value) -> str:
    return "—" if value is None else f"{value:.6g}"


def _stamp_text(row: dict) -> str:
    """What a topic's stamps say, its problems first: gaps, stamps not monotonic."""
    gaps, lag = row["gaps"], row["lag_ms"]
    flags = []
    if gaps["count"]:
        flags.append(f"gaps: {gaps['count']} ({gaps['seconds']:.4g} s in all, about "
                     f"{gaps['missing']} samples missing; the longest {gaps['longest']:.4g} s "
                     f"from t = {gaps['at']:.4g} s)")
    if row["out_of_order"] or row["repeated"] or row["unset"]:
        flags.append(f"stamps not monotonic: {row['out_of_order']} received out of order (put "
                     f"in order), {row['repeated']} repeated and {row['unset']} unset (left out)")
    if row["stamps"] == "header":
        flags.append(f"header stamps, received {lag['p50']:.3g} ms after them (p50; "
                     f"{lag['min']:.3g} to {lag['max']:.3g} ms)")
    else:
        flags.append("no header stamp set: the receive times are used")
    return "; ".join(flags if gaps["count"] else [*flags, "no gap"])
