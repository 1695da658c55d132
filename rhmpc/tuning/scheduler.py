"""Reaching a Dask scheduler with deadlines: connected, greeted, and its first answer in time.

dask.distributed's client bounds the connection with its timeout but then waits without end
for the scheduler's greeting (the handshake every Dask endpoint sends as soon as it accepts a
connection), and reads the first 8 bytes of whatever arrives as the size of the message to
come: a peer that accepts and never answers hangs the client, and one that answers with other
bytes (an SSH server's ``SSH-2.0-``) asks it to allocate exbibytes. So :func:`connect` first
opens a connection of its own with deadlines (:data:`CONNECT_TIMEOUT_S` to connect,
:data:`ANSWER_TIMEOUT_S` for the greeting) and checks that the greeting is framed as Dask
frames its messages, then starts the client and asks for the cluster's threads within
:data:`ANSWER_TIMEOUT_S`. Each failure is one :class:`~rhmpc.errors.UsageError` naming the
address.
"""

from __future__ import annotations

import socket
import struct
import threading
from typing import Any

from rhmpc.errors import UsageError

__all__ = ["ANSWER_TIMEOUT_S", "CONNECT_TIMEOUT_S", "DEFAULT_PORT", "MAX_GREETING", "connect",
           "greeting_check"]

#: Seconds to connect to the scheduler's address.
CONNECT_TIMEOUT_S = 10.0
#: Seconds for the scheduler's greeting, and again for the client's start and first answer:
#: a scheduler answers within milliseconds, one busy with a large graph within seconds.
ANSWER_TIMEOUT_S = 20.0
#: Dask's scheduler port where the address names none.
DEFAULT_PORT = 8786
#: The largest greeting read [B]: a handshake is a small table (about 200 B).
MAX_GREETING = 1 << 20
#: The most frames a greeting is split into.
MAX_FRAMES = 64


def _host_port(scheduler: str) -> tuple[str, int, bool] | None:
    """(host, port, TLS) of a ``tcp://`` or ``tls://`` address (or one without a scheme),
    None for another transport."""
    scheme, sep, rest = scheduler.partition("://")
    scheme, rest = (scheme, rest) if sep else ("tcp", scheduler)
    if scheme not in ("tcp", "tls"):
        return None
    rest = rest.rstrip("/")
    if rest.startswith("["):  # [IPv6]:port
        host, _, port = rest[1:].partition("]")
        port = port.lstrip(":")
    else:
        host, _, port = rest.rpartition(":") if ":" in rest else (rest, "", "")
    if not host or not (port.isdigit() or port == "") or int(port or DEFAULT_PORT) > 65535:
        raise UsageError(f"--scheduler {scheduler}: expected tcp://HOST:PORT")
    return host, int(port or DEFAULT_PORT), scheme == "tls"


def _receive(sock: socket.socket, n: int) -> bytes:
    """Up to ``n`` bytes: fewer only when the peer closed the connection."""
    data = b""
    while len(data) < n:
        chunk = sock.recv(n - len(data))
        if not chunk:
            break
        data += chunk
    return data


def greeting_check(head: bytes, body: bytes | None = None) -> str | None:
    """What is wrong with a greeting whose first 8 bytes are ``head`` (the size of the frames
    that follow, as Dask writes it) and whose frames are ``body``; None when it is Dask's."""
    if len(head) < 8:
        return "closed the connection without a greeting"
    (size,) = struct.unpack("=Q", head)
    if not 16 <= size <= MAX_GREETING:
        return f"answered {head!r}, not a Dask message"
    if body is None:
        return None
    if len(body) < size:
        return "closed the connection within its greeting"
    (frames,) = struct.unpack_from("=Q", body)
    if not 1 <= frames <= MAX_FRAMES or 8 * (1 + frames) > size:
        return f"answered {head + body[:16]!r}…, not a Dask message"
    return None


def _probe(scheduler: str, host: str, port: int, tls: bool) -> None:
    """Connect within :data:`CONNECT_TIMEOUT_S` and, without TLS, read a greeting framed as
    Dask's within :data:`ANSWER_TIMEOUT_S`; a ``UsageError`` naming ``scheduler`` else."""
    try:
        sock = socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S)
    except TimeoutError:
        raise UsageError(f"--scheduler {scheduler}: no connection within "
                         f"{CONNECT_TIMEOUT_S:g} s") from None
    except OSError as exc:
        raise UsageError(f"--scheduler {scheduler}: cannot connect: {exc.strerror or exc}"
                         ) from None
    with sock:
        if tls:
            return
        sock.settimeout(ANSWER_TIMEOUT_S)
        try:
            head = _receive(sock, 8)
            problem = greeting_check(head)
            if problem is None:
                problem = greeting_check(head, _receive(sock, struct.unpack("=Q", head)[0]))
        except TimeoutError:
            problem = f"no greeting within {ANSWER_TIMEOUT_S:g} s of connecting"
        except OSError as exc:
            problem = f"the connection failed: {exc.strerror or exc}"
    if problem is not None:
        raise UsageError(f"--scheduler {scheduler}: {problem}: not a Dask scheduler (a "
                         "scheduler greets each connection at once)")


def _start(scheduler: str, out: dict[str, Any]) -> None:
    """The client and its cluster's threads into ``out`` (or the exception)."""
    try:
        from distributed import Client

        client = Client(scheduler, timeout=f"{ANSWER_TIMEOUT_S:g}s")
        out["client"] = client
        out["threads"] = sum(client.nthreads().values())
    except BaseException as exc:  # handed to the caller's thread
        out["error"] = exc


def connect(scheduler: str) -> tuple[Any, int]:
    """A ``distributed.Client`` of the scheduler at ``scheduler`` and its cluster's threads.

    Raises
    ------
    UsageError
        dask.distributed missing, the address malformed or unreachable, a peer that is not a
        Dask scheduler, or no answer within the deadlines (module docstring).
    """
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise UsageError("--scheduler needs dask.distributed: pip install 'rhmpc[dask]'"
                         ) from None
    address = _host_port(scheduler)
    if address is not None:
        _probe(scheduler, *address)
    out: dict[str, Any] = {}
    thread = threading.Thread(target=_start, args=(scheduler, out), daemon=True,
                              name="dask-client-start")
    thread.start()
    thread.join(CONNECT_TIMEOUT_S + 2 * ANSWER_TIMEOUT_S)
    if thread.is_alive() or "error" in out:
        if "client" in out:
            out["client"].close(timeout=1)
        error = out.get("error")
        reason = (f"no answer within {CONNECT_TIMEOUT_S + 2 * ANSWER_TIMEOUT_S:g} s"
                  if error is None else " ".join(str(error).split()) or type(error).__name__)
        raise UsageError(f"--scheduler {scheduler}: cannot start a Dask client: {reason}")
    return out["client"], out["threads"]
