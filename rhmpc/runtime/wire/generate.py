"""Write what the wire's tables give: the C header and the deployment guide's tables.

``python -m rhmpc.runtime.wire.generate`` rewrites ``rhmpc/runtime/export/rhmpc_wire.h`` (from
the template ``rhmpc_wire.h.in`` beside this module) and the part of
``docs/guide/your-robot.md`` between ``<!-- wire:begin -->`` and ``<!-- wire:end -->``. The
tests compare both files with :func:`c_header` and :func:`guide_tables`.
"""

from __future__ import annotations

import re
import sys
from importlib.resources import files
from pathlib import Path

from rhmpc import io
from rhmpc.runtime.wire.codec import HEAD, MAC_BYTES, OFFSETS
from rhmpc.runtime.wire.table import (
    AUTH,
    DROPS,
    HEADER,
    KINDS,
    MAX_POINTS,
    MAX_ROWS,
    MAX_STEP,
    REPORT,
    VERSION,
    layout_digest,
)

__all__ = ["GUIDE_MARKS", "c_header", "guide_tables", "main"]

#: The lines that enclose the generated part of the guide.
GUIDE_MARKS = ("<!-- wire:begin -->", "<!-- wire:end -->")


#: The C header's comments in ASCII.
_ASCII = str.maketrans({"→": "->", "…": "...", "·": "*", "’": "'"})


def _comment_rows(rows: list[str]) -> str:
    return "\n".join(f" *   {row}".translate(_ASCII) for row in rows)


def _by_number(values: dict[int, str], empty: str) -> str:
    top = max(k.number for k in KINDS)
    return ", ".join(values.get(i, empty) for i in range(top + 1))


def c_header() -> str:
    """The text of ``rhmpc_wire.h``."""
    header = [f"{OFFSETS[f.name]:>3} {f.ctype:<9} {f.name:<9} {f.doc}"
              + (f" [{f.unit}]" if f.unit else "") for f in HEADER]
    kinds = [f"{k.number} {k.name} ({k.route}): {k.doc} [{k.unit}]" for k in KINDS]
    subs = {
        "VERSION": str(VERSION), "DIGEST": layout_digest(), "HEADER_BYTES": str(HEAD.size),
        "MAC_BYTES": str(MAC_BYTES), "AUTH": AUTH[0], "MAX_ROWS": str(MAX_ROWS),
        "MAX_POINTS": str(MAX_POINTS), "MAX_STEP": str(MAX_STEP),
        "HEADER_COMMENT": _comment_rows(header), "KINDS_COMMENT": _comment_rows(kinds),
        "OFFSETS": "\n".join(f"#define RHMPC_WIRE_AT_{f.name.upper()} {OFFSETS[f.name]}"
                             for f in HEADER),
        "KIND_DEFINES": "\n".join(f"#define RHMPC_{k.name.upper()} {k.number}" for k in KINDS),
        "N_KINDS": str(max(k.number for k in KINDS) + 1),
        "KIND_NAMES": _by_number({k.number: f'"{k.name}"' for k in KINDS}, '""'),
        "ROWS_MIN": _by_number({k.number: str(k.rows[0]) for k in KINDS}, "0"),
        "ROWS_MAX": _by_number({k.number: str(k.rows[1]) for k in KINDS}, "0"),
        "WIDTH": _by_number({k.number: str(k.width or 0) for k in KINDS}, "0"),
        "DROP_ENUM": "\n".join(f"  RHMPC_DROP_{name.upper()}, /* {doc} */" for name, doc in DROPS),
        "DROP_NAMES": ", ".join(f'"{name}"' for name, _ in DROPS),
        "REPORT_ENUM": "\n".join(f"  RHMPC_REPORT_{key.upper()}, /* {doc} */"
                                 for key, doc in REPORT),
        "REPORT_NAMES": ", ".join(f'"{key}"' for key, _ in REPORT),
    }
    text = files(__package__).joinpath("rhmpc_wire.h.in").read_text()
    for key, value in subs.items():
        text = text.replace(f"@{key}@", value)
    leftover = re.search(r"@[A-Z_]+@", text)
    if leftover:
        raise RuntimeError(f"rhmpc_wire.h.in: unreplaced placeholder {leftover.group()}")
    return text


def guide_tables() -> str:
    """The guide's tables of the format (Markdown), between :data:`GUIDE_MARKS`."""
    lines = [GUIDE_MARKS[0], "",
             f"Version {VERSION}; one UDP datagram per message, little-endian: a {HEAD.size}-byte "
             f"header, then `rows × width` float64 values, then the {AUTH[0]} code "
             f"({MAC_BYTES} bytes) of {AUTH[2]}.", "",
             "| offset | type | field | unit | what it is |", "|---|---|---|---|---|"]
    lines += [f"| {OFFSETS[f.name]} | `{f.ctype}` | `{f.name}` | {f.unit} | {f.doc} |"
              for f in HEADER]
    lines += ["", "| kind | CRTK name | rows | width | unit | from → to | what a row holds |",
              "|---|---|---|---|---|---|---|"]
    lines += [f"| {k.number} | `{k.name}` | {k.rows[0]} … {k.rows[1]} | "
              f"{k.width or 'joints'} | {k.unit} | {k.route} | {k.doc} |" for k in KINDS]
    lines += ["", "| a receiver drops | when |", "|---|---|"]
    lines += [f"| `{name}` | {doc} |" for name, doc in DROPS]
    lines += ["", "The controller program's report (`PREFIX.json`):", "",
              "| key | what it holds |", "|---|---|"]
    lines += [f"| `{key}` | {doc} |" for key, doc in REPORT]
    return "\n".join([*lines, "", GUIDE_MARKS[1]])


def _guide_with_tables(text: str) -> str:
    begin, end = (text.index(mark) for mark in GUIDE_MARKS)
    return text[:begin] + guide_tables() + text[end + len(GUIDE_MARKS[1]):]


def main(root: Path) -> None:
    """Rewrite the header and the guide's tables under the repository ``root``."""
    io.write_text(root / "rhmpc" / "runtime" / "export" / "rhmpc_wire.h", c_header(), root=root)
    guide = root / "docs" / "guide" / "your-robot.md"
    io.write_text(guide, _guide_with_tables(io.read_text(guide)), root=root)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path.cwd())
