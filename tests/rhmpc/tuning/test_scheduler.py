"""Reaching a Dask scheduler with deadlines: a peer that is not Dask is one line naming it."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest

from rhmpc.errors import UsageError
from rhmpc.tuning import scheduler
from rhmpc.tuning.runner import executors


def serve(answer: bytes | None, close: bool = False) -> Iterator[str]:
    """A peer on a free local port: it accepts, then sends ``answer`` (None: nothing), and
    closes the connection with ``close``."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    held = []

    def accept() -> None:
        while True:
            try:
                conn, _ = server.accept()
            except OSError:
                return
            held.append(conn)
            if answer:
                conn.sendall(answer)
            if close:
                conn.close()

    threading.Thread(target=accept, daemon=True).start()
    try:
        yield f"tcp://127.0.0.1:{server.getsockname()[1]}"
    finally:
        server.close()
        for conn in held:
            conn.close()


@pytest.fixture
def quick(monkeypatch: pytest.MonkeyPatch) -> None:
    """Deadlines of a fraction of a second."""
    monkeypatch.setattr(scheduler, "CONNECT_TIMEOUT_S", 1.0)
    monkeypatch.setattr(scheduler, "ANSWER_TIMEOUT_S", 0.3)


@pytest.mark.parametrize("answer, close, says", [
    (None, False, "no greeting within 0.3 s"),
    (b"SSH-2.0-OpenSSH_9.2p1\r\n", False, "answered b'SSH-2.0-', not a Dask message"),
    (None, True, "closed the connection without a greeting"),
    (b"\xff" * 8, False, "not a Dask message"),
    ((40).to_bytes(8, "little") + (10**9).to_bytes(8, "little") + bytes(32), False,
     "not a Dask message"),
])
def test_a_peer_that_is_not_dask_is_one_line_naming_it(quick, answer, close, says) -> None:
    pytest.importorskip("distributed")
    for address in serve(answer, close):
        with pytest.raises(UsageError) as info:
            executors(None, address, 2)
        message = str(info.value)
        assert message.startswith(f"--scheduler {address}: ") and says in message, message
        assert "not a Dask scheduler" in message and "\n" not in message


def test_an_address_nobody_listens_at(quick) -> None:
    pytest.importorskip("distributed")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # free once closed
    with pytest.raises(UsageError, match=rf"--scheduler tcp://127.0.0.1:{port}: cannot "):
        executors(None, f"tcp://127.0.0.1:{port}", 2)


@pytest.mark.parametrize("address, parsed", [
    ("tcp://10.0.0.2:8786", ("10.0.0.2", 8786, False)),
    ("10.0.0.2:9000", ("10.0.0.2", 9000, False)),
    ("tls://host", ("host", scheduler.DEFAULT_PORT, True)),
    ("tcp://[::1]:8786", ("::1", 8786, False)),
    ("inproc://10.0.0.2/1/2", None),
])
def test_addresses(address, parsed) -> None:
    assert scheduler._host_port(address) == parsed


def test_a_dask_scheduler_passes(quick) -> None:
    """A scheduler of dask.distributed greets within the deadline; the client starts."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=0, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None,
                                  silence_logs=40) as cluster:
        client, threads = scheduler.connect(cluster.scheduler_address)
        client.close()
    assert threads == 0
