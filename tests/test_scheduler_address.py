"""``--scheduler``: a malformed address, a dead port, a silent port and a port that talks garbage.

Each must end in exit 2 with one line naming the address, within the documented bound (README,
``fixplan robust``: "a scheduler that cannot be reached within 10 s"): the connection is given
``ClusterSettings.connect_timeout_s``, and the rest is starting Python and reading the fixture.
Before: ``tcp://[::1`` exited 3 after 21 s, a silent port hung for more than 180 s, and a
port that sends garbage exited 3 with a traceback. The elapsed time is a hang check
(a bound), not a speed target.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator

import pytest
from conftest import PROBLEMS, ROOT, run_cli

from fixplan.cluster import DEFAULT_PORT, check_address, dask_client
from fixplan.errors import InputError
from fixplan.settings import DEFAULT

JAMS = PROBLEMS / "naive-order-jams.toml"
DOCUMENTED_BOUND_S = 10.0  # README: exit 2 "within 10 s"


class _Server:
    """A loopback TCP server that accepts every connection and then stays silent or sends ``reply``."""

    def __init__(self, reply: bytes | None):
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(16)
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.reply = reply
        self.accepted = 0
        self._stop = threading.Event()
        self._conns: list[socket.socket] = []
        self._thread = threading.Thread(target=self._serve, daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            self.accepted += 1
            self._conns.append(conn)
            if self.reply is not None:
                try:
                    conn.sendall(self.reply)
                except OSError:
                    pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for c in self._conns:
            c.close()
        self.sock.close()


@pytest.fixture
def silent_port() -> Iterator[_Server]:
    server = _Server(None)
    yield server
    server.close()


# a frame count of 2**63-ish and then noise: Dask tried to allocate exabytes (MemoryError, exit 3)
GARBAGE = b"\xff\x00garbage" * 1000


@pytest.fixture
def garbage_port() -> Iterator[_Server]:
    server = _Server(GARBAGE)
    yield server
    server.close()


def _assert_refused(args: list[str], address: str, *, needle: str | None = None) -> float:
    t0 = time.monotonic()
    proc = run_cli(*args, "--scheduler", address, timeout=120, cwd=ROOT)
    elapsed = time.monotonic() - t0
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert repr(address) in lines[0] or address in lines[0], lines[0]
    if needle is not None:
        assert needle in lines[0], lines[0]
    assert elapsed < DOCUMENTED_BOUND_S, f"{elapsed:.1f} s"
    return elapsed


def test_the_connection_time_fits_the_documented_bound():
    # about 2 s for Python, the imports and the fixture, measured: keep 3 s of room
    assert DEFAULT.cluster.connect_timeout_s <= DOCUMENTED_BOUND_S - 3.0


@pytest.mark.parametrize("command", [["robust", str(JAMS)], ["solve", "--batch", str(PROBLEMS)]])
def test_a_silent_port_exits_2_within_the_bound(silent_port, command):
    """The port accepts and never answers (Dask's handshake read had no timeout)."""
    address = f"tcp://127.0.0.1:{silent_port.port}"
    _assert_refused(command, address, needle="handshake")
    assert silent_port.accepted >= 1  # the connection was made: the hang was in the handshake


@pytest.mark.parametrize("command", [["robust", str(JAMS)], ["solve", "--batch", str(PROBLEMS)]])
def test_a_port_sending_garbage_exits_2(garbage_port, command):
    """Garbage where Dask's handshake should be."""
    _assert_refused(command, f"tcp://127.0.0.1:{garbage_port.port}", needle="Dask")


def test_a_closed_port_exits_2_within_the_bound():
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    _assert_refused(["robust", str(JAMS)], f"tcp://127.0.0.1:{port}", needle="no connection")


@pytest.mark.parametrize(
    ("address", "reason"),
    [
        ("tcp://[::1", "closing ']'"),  # exited 3 after 21 s
        ("tcp://[::1]x", "after the IPv6 address"),
        ("tcp://[nope]:8786", "not an IPv6 address"),
        ("tcp://::1:8786", "in brackets"),
        ("tcp://127.0.0.1:0", "1..65535"),
        ("tcp://127.0.0.1:65536", "1..65535"),
        ("tcp://127.0.0.1:-1", "1..65535"),
        ("tcp://127.0.0.1:http", "1..65535"),
        ("tcp://127.0.0.1:", "1..65535"),
        ("tcp://:8786", "no host"),
        ("tcp://", "no host"),
        ("tcp://300.1.1.1:8786", "not an IPv4 address"),
        ("tcp://host_name:8786", "not a host name"),
        ("tcp://-host:8786", "not a host name"),
        ("tcp://a..b:8786", "not a host name"),
        ("tcp://host/path:8786", "not a host name"),
        ("tcp://host:8786/x", "1..65535"),
        ("tls://127.0.0.1:8786", "'tls://' is not supported"),
        ("inproc://x", "'inproc://' is not supported"),
        ("localhost:8786", "no scheme"),
        ("tcp://a b:1", "spaces"),
        ("tcp://a\x1b[2J:1", "control characters"),
    ],
)
def test_malformed_addresses_are_refused_before_connecting(address, reason):
    with pytest.raises(InputError, match="check_address.address expects an address like tcp://HOST:8786") as err:
        check_address(address)
    assert reason in str(err.value)
    assert "\n" not in str(err.value) and str(err.value).isprintable()


def test_d8_malformed_ipv6_exits_2_at_once():
    _assert_refused(["robust", str(JAMS)], "tcp://[::1", needle="closing ']'")


@pytest.mark.parametrize(
    ("address", "host", "port"),
    [
        ("tcp://127.0.0.1:8786", "127.0.0.1", 8786),
        ("tcp://[::1]:1", "::1", 1),
        ("tcp://[fe80::1%eth0]:65535", "fe80::1%eth0", 65535),
        ("tcp://scheduler.example.org", "scheduler.example.org", DEFAULT_PORT),
        ("tcp://[::1]", "::1", DEFAULT_PORT),
        ("tcp://node-7:9000", "node-7", 9000),
    ],
)
def test_well_formed_addresses_give_host_and_port(address, host, port):
    assert check_address(address) == (host, port)


def test_the_library_raises_input_error_for_a_silent_port(silent_port):
    """dask_client itself (not only the CLI) gives up within its timeout, naming the stage."""
    t0 = time.monotonic()
    with (
        pytest.raises(InputError, match="no answer to Dask's handshake"),
        dask_client(f"tcp://127.0.0.1:{silent_port.port}", timeout_s=1.0),
    ):
        pass
    assert time.monotonic() - t0 < 1.0 + 2.0  # the timeout, plus room for a loaded machine
