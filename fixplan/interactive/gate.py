"""A token gate in front of viser for ``fixplan haptic --host H --token T``.

viser has no authentication, so with ``--host`` other than 127.0.0.1 this gate is the only
listener: viser itself listens on a Unix socket in a folder only this user can enter
(:class:`PrivateSocket`, :func:`viser_on_unix_socket`), never on a TCP port that another process
on the machine could reach without the token. A request is let through when it carries the
token as ``?token=T`` (the printed URL) or in the ``fixplan_token`` cookie that the gate sets on
the first page load; anything else gets ``403 Forbidden``, the websocket included. Pages are
fetched from viser over the socket and passed on; a websocket is relayed frame by frame.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import http
import http.client
import os
import shutil
import socket
import tempfile
import threading
from collections.abc import Iterator
from http.cookies import SimpleCookie
from typing import Any
from urllib.parse import parse_qs, urlsplit

from fixplan.errors import InputError

COOKIE = "fixplan_token"


def token_ok(path: str, cookie_header: str | None, token: str) -> tuple[bool, bool]:
    """(allowed, came with the query): the token in ``?token=`` or the cookie, compared in constant time."""
    query = parse_qs(urlsplit(path).query).get("token", [])
    if any(hmac.compare_digest(q.encode(), token.encode()) for q in query):
        return True, True
    if cookie_header:
        jar: SimpleCookie = SimpleCookie()
        try:
            jar.load(cookie_header)
        except Exception:  # noqa: BLE001 - a malformed cookie header is no token
            return False, False
        morsel = jar.get(COOKIE)
        if morsel is not None and hmac.compare_digest(morsel.value.encode(), token.encode()):
            return True, False
    return False, False


class PrivateSocket:
    """A path for a Unix socket in a fresh folder only this user can enter (mode 0700); :meth:`close` removes both."""

    def __init__(self) -> None:
        self.folder = tempfile.mkdtemp(prefix="fixplan-haptic-")
        self.path = os.path.join(self.folder, "viser.sock")

    def close(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


@contextlib.contextmanager
def viser_on_unix_socket(path: str) -> Iterator[None]:
    """While a ``viser.ViserServer`` is built inside, its server listens on the Unix socket ``path``, not TCP.

    viser binds ``host:port`` with ``websockets.asyncio.server.serve`` and has no option for a
    socket; its constructor returns once the server listens, so the substitution lasts exactly
    that long. ``get_port()`` of that server means nothing.
    """
    import websockets.asyncio.server as ws_server

    original = ws_server.serve

    def on_socket(handler: Any, host: Any = None, port: Any = None, **kwargs: Any) -> Any:  # noqa: ARG001
        return original(handler, unix=True, path=path, **kwargs)

    ws_server.serve = on_socket  # type: ignore[assignment,misc]
    try:
        yield
    finally:
        ws_server.serve = original  # type: ignore[misc]


class _UnixHTTPConnection(http.client.HTTPConnection):
    """An HTTP connection to a server on a Unix socket."""

    def __init__(self, path: str, timeout: float):
        super().__init__("localhost", timeout=timeout)
        self.socket_path = path

    def connect(self) -> None:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.settimeout(self.timeout)
        sock.connect(self.socket_path)
        self.sock = sock


def _fetch(socket_path: str, path: str) -> tuple[bytes, int, str]:
    """GET ``path`` from the server on ``socket_path``: (body, status, content type)."""
    conn = _UnixHTTPConnection(socket_path, timeout=10.0)
    try:
        conn.request("GET", path)
        r = conn.getresponse()
        return r.read(), r.status, r.headers.get("Content-Type", "text/html")
    finally:
        conn.close()


class TokenGate:
    """Listen on ``host:port``, check the token, and relay to viser on the Unix socket ``inner``."""

    def __init__(self, host: str, port: int, inner: str, token: str):
        self.host, self.port = host, port
        self.inner = inner
        self.token = token
        self.refused = 0
        self.relayed = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopped: asyncio.Event | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    def start(self) -> int:
        """Start the gate's thread; the port it listens on."""
        self._thread = threading.Thread(target=self._run, name="fixplan-token-gate", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._error is not None:
            raise InputError(f"TokenGate.host {self.host} TokenGate.port {self.port}: cannot listen: {self._error}")
        return self.port

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        try:
            self._loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported by start()
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _serve(self) -> None:
        from websockets.asyncio.server import serve
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        inner = self.inner

        def process_request(connection: Any, request: Any) -> Any:
            allowed, via_query = token_ok(request.path, request.headers.get("Cookie"), self.token)
            if not allowed:
                self.refused += 1
                return Response(http.HTTPStatus.FORBIDDEN, "Forbidden", Headers({"Content-Type": "text/plain"}),
                                b"fixplan haptic: a token is required (open the URL the command printed)\n")  # fmt: skip
            if request.headers.get("Upgrade", "").lower() == "websocket":
                return None  # the handshake goes on; handler() relays
            path = urlsplit(request.path).path or "/"
            try:
                body, status, ctype = _fetch(inner, path)
            except OSError as exc:
                body, status, ctype = f"fixplan haptic: {exc}\n".encode(), 502, "text/plain"
            headers = Headers({"Content-Type": ctype, "Content-Length": str(len(body))})
            if via_query:
                headers["Set-Cookie"] = f"{COOKIE}={self.token}; Path=/; HttpOnly; SameSite=Strict"
            return Response(status, http.HTTPStatus(status).phrase, headers, body)

        async def handler(ws: Any) -> None:
            from websockets.asyncio.client import unix_connect
            from websockets.exceptions import ConnectionClosed

            protocols = [ws.subprotocol] if ws.subprotocol else None
            self.relayed += 1
            async with unix_connect(inner, "ws://localhost/", subprotocols=protocols, max_size=None,
                                    compression=None) as viser_ws:  # fmt: skip

                async def pump(a: Any, b: Any) -> None:
                    try:
                        async for msg in a:
                            await b.send(msg)
                    except ConnectionClosed:
                        pass  # either side left: the other is closed below

                tasks = [asyncio.ensure_future(pump(ws, viser_ws)), asyncio.ensure_future(pump(viser_ws, ws))]
                _, pending = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
                for t in pending:
                    t.cancel()

        def select_subprotocol(_conn: Any, offered: Any) -> Any:
            return next((p for p in offered if p.startswith("viser-v")), None)

        self._stopped = asyncio.Event()
        async with serve(handler, self.host, self.port, process_request=process_request, max_size=None,
                         compression=None, select_subprotocol=select_subprotocol) as server:  # fmt: skip
            sockets = server.sockets
            if sockets:
                self.port = int(sockets[0].getsockname()[1])
            self._ready.set()
            await self._stopped.wait()

    def stop(self) -> None:
        loop, stopped = self._loop, self._stopped
        if loop is not None and stopped is not None and not loop.is_closed():
            loop.call_soon_threadsafe(stopped.set)
        if self._thread is not None:
            self._thread.join(timeout=5.0)
