"""The boundary of rhmpc (``rhmpc.io``): files in through one guarded reader, out through one
atomic writer, and the bounds of every count a user sets.

==============  =================================================================
``reader``      :func:`open_input` and the readers on it (bytes, text, TOML, JSON):
                regular files only, sizes and depths bounded, errors naming the file
``npz``         :class:`NpzArchive`: ``.npz`` members checked before they are read
``writer``      :class:`AtomicFile`, :func:`check_output`: a temporary file renamed over
                the target; never through a link, outside its folder or onto an input
``limits``      :data:`BOUNDS` and :data:`FILE_BYTES`: the one table of bounds
``kinds``       :func:`check_kinds`: a settings table's values against its dataclass's
                annotations (a number, a string, a list, a table)
==============  =================================================================

It sits below every other package (``rhmpc.predictors`` and ``rhmpc.robots`` included) and
depends on the standard library and NumPy only, so that each layer reads and writes its files
the same way. Modules import it as ``from rhmpc import io`` (``io.read_bytes``,
``io.FileError``); one that also needs the standard library's ``io`` imports its names
(``from io import BytesIO``).
"""

from rhmpc.io.kinds import check_kinds
from rhmpc.io.limits import BOUNDS, FILE_BYTES, Bound, check, largest
from rhmpc.io.reader import (
    FileError,
    json_loads,
    open_input,
    read_bytes,
    read_json,
    read_text,
    read_toml,
    tracking_inputs,
)
from rhmpc.io.writer import (
    AtomicFile,
    atomic_write,
    check_output,
    file_stem,
    make_folder,
    save_figure,
    write_bytes,
    write_text,
)

__all__ = [
    "BOUNDS", "FILE_BYTES", "AtomicFile", "Bound", "FileError", "NpzArchive", "atomic_write",
    "check", "check_kinds", "check_output", "file_stem", "json_loads", "largest", "make_folder",
    "open_input", "read_bytes", "read_json", "read_text", "read_toml", "save_figure",
    "tracking_inputs", "write_bytes", "write_text",
]


def __getattr__(name: str):
    if name == "NpzArchive":  # NumPy is imported only when an archive is read
        from rhmpc.io.npz import NpzArchive

        return NpzArchive
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
