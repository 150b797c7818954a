"""``fixplan haptic --host H --token T`` exposes nothing without the token, and ``--json`` stays JSON.

The gate answered 403, but viser itself listened on 127.0.0.1 (its URL printed on stderr)
and served the page and a websocket to any process on the machine without the token. Every
socket the process listens on is enumerated (psutil) and tried without the token.
A websocket client of another viser version made viser print "Version mismatch" on stdout,
after which ``--json`` was no longer one document.
"""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.request

import psutil
import pytest
from conftest import CLI

from fixplan.interactive import protocol

TOKEN = "tok-0123456789"


@pytest.fixture(scope="module")
def session():
    """A token-gated session on 127.0.0.2 with the UDP bridge; ended with Ctrl-C (SIGINT) by the tests."""
    proc = subprocess.Popen(
        [*CLI, "haptic", "--host", "127.0.0.2", "--token", TOKEN, "--port", "0", "--device", "udp:0",
         "--no-browser", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    lines = []
    while True:  # the page's URL is printed once everything listens
        line = proc.stderr.readline()
        assert line, f"haptic ended early: {''.join(lines)}"
        lines.append(line)
        if (m := re.search(r"http://127\.0\.0\.2:(\d+)/\?token=", line)) is not None:
            break
    state = {"proc": proc, "port": int(m.group(1)), "stderr": lines}
    yield state
    if proc.poll() is None:
        proc.kill()
        proc.communicate()


def listening(pid: int) -> tuple[list[tuple[str, int]], list[tuple[str, int]]]:
    """The TCP addresses ``pid`` listens on and its bound UDP addresses."""
    conns = psutil.Process(pid).net_connections(kind="inet")
    tcp = sorted({(c.laddr.ip, c.laddr.port) for c in conns if c.type == socket.SOCK_STREAM and c.status == "LISTEN"})
    udp = sorted({(c.laddr.ip, c.laddr.port) for c in conns if c.type == socket.SOCK_DGRAM and c.laddr})
    return tcp, udp


def test_no_listener_answers_without_the_token(session):
    import viser
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    tcp, udp = listening(session["proc"].pid)
    assert tcp == [("127.0.0.2", session["port"])]  # the gate alone: viser is on a private Unix socket
    for ip, port in tcp:
        with pytest.raises(urllib.error.HTTPError) as page:
            urllib.request.urlopen(f"http://{ip}:{port}/", timeout=10)  # noqa: S310 - a test's own server
        assert page.value.code == 403
        with pytest.raises(InvalidStatus, match="403"):
            connect(f"ws://{ip}:{port}/", subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10).close()
    # the UDP bridge answers a HELLO only when it carries the token
    for ip, port in udp:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as device, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:  # fmt: skip
            device.settimeout(1.0)
            reply = None
            for _ in range(30):  # the loop answers once the session runs (just after the URL is printed)
                device.sendto(protocol.encode_hello(TOKEN), (ip, port))
                try:
                    reply = device.recvfrom(65536)[0]
                    break
                except TimeoutError:
                    continue
            assert reply is not None and protocol.message_type(reply) == protocol.CONFIG
            stranger.settimeout(2.0)  # the loop runs: silence now is a refusal
            stranger.sendto(protocol.encode_hello(None), (ip, port))
            stranger.sendto(protocol.encode_hello("wrong-token"), (ip, port))
            with pytest.raises(TimeoutError):
                stranger.recvfrom(65536)
    # the page and the websocket do come through the gate with the token
    url = f"http://127.0.0.2:{session['port']}/?token={TOKEN}"
    with urllib.request.urlopen(url, timeout=10) as r:  # noqa: S310 - a test's own server
        assert r.status == 200


def test_json_stays_one_document_when_viser_prints_and_no_inner_url_is_shown(session):
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    # a client of another viser version: viser refuses it and prints a line about it
    with connect(f"ws://127.0.0.2:{session['port']}/?token={TOKEN}", subprotocols=["viser-v0.0.0"],
                 open_timeout=10) as ws:  # fmt: skip
        with pytest.raises((ConnectionClosed, TimeoutError)):
            ws.recv(timeout=10)
    time.sleep(0.5)
    proc = session["proc"]
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    stderr = "".join(session["stderr"]) + err
    assert proc.returncode in (0, 1), stderr
    doc = json.loads(out)  # one document: viser's line went to stderr
    assert "status" in doc and "loop" in doc
    assert "Version mismatch" in stderr
    # every URL printed is the gate's: none names another port, or viser's socket
    ports = {int(p) for p in re.findall(r"(?:https?|wss?)://[^\s:/]+:(\d+)", stderr)}
    assert ports == {session["port"]}, stderr
    assert "viser.sock" not in stderr and "Websocket" not in stderr


def test_ctrl_c_ends_a_session_started_with_sigint_ignored():
    """A session started in the background of a script inherits SIGINT ignored (``cmd &`` in a
    non-interactive shell); it promises "Ctrl-C ends the session", so it must still end on SIGINT
    (with its one JSON document once the session runs). Before the fix it waited for ever (found when
    this suite ran in the background)."""
    proc = subprocess.Popen(
        [*CLI, "haptic", "--host", "127.0.0.2", "--token", TOKEN, "--port", "0", "--device", "udp:0",
         "--no-browser", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN),  # noqa: PLW1509 - the test's point
    )  # fmt: skip
    try:
        while "Ctrl-C ends the session" not in (line := proc.stderr.readline()):
            assert line, "haptic ended early"
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    # ended (not killed): in the session, with its JSON; or while it was still starting, 130 as any command
    assert proc.returncode in (0, 1, 130)
    if proc.returncode != 130:
        assert json.loads(out)["status"] in ("short", "reached")
