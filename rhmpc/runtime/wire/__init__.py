"""The wire format between the processes of a deployment, and a process's end of it.

Declared once in :mod:`.table` (the header's fields, the kinds with their CRTK names and row
layouts, the authentication code, the receivers' drops and the controller program's report
keys); :mod:`.codec` is the Python codec built from it and :mod:`.generate` writes the C header
``rhmpc_wire.h`` and the deployment guide's tables from it. Every message is sealed with
HMAC-SHA-256 under the run's key (:mod:`.key`); a receiver (:class:`Receiver`) authenticates a
datagram before it reads it, then judges its kind, its bounds (:class:`Bounds`) and its
sequence number, and counts what it drops.
"""

from rhmpc.runtime.wire.bounds import WORKSPACE_RADIUS, Bounds
from rhmpc.runtime.wire.codec import Dropped, Message, seal, unseal
from rhmpc.runtime.wire.key import KEY_BYTES, KeyFileError, new_key, read_key, write_key
from rhmpc.runtime.wire.link import Link, Receiver, TrackerClient, bind, run_clock
from rhmpc.runtime.wire.table import DROPS, KINDS, MAX_STEP, REPORT, VERSION

__all__ = ["DROPS", "KEY_BYTES", "KINDS", "MAX_STEP", "REPORT", "VERSION", "WORKSPACE_RADIUS",
           "Bounds", "Dropped", "KeyFileError", "Link", "Message", "Receiver", "TrackerClient",
           "bind", "new_key", "read_key", "run_clock", "seal", "unseal", "write_key"]
