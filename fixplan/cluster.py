"""Running independent tasks on a Dask cluster: in-process local workers, or a scheduler's address.

``fixplan robust`` (one task per perturbed world) and ``fixplan solve --batch`` (one task per
fixture file) both go through :func:`dask_client` and :func:`run_tasks`.

Local default: a :class:`distributed.LocalCluster` of worker *processes*, one thread each, as
many as there are cores (at most one per task). Threads were measured and lose: a verification
is mostly Python (the executor re-solves its cone program at 200 Hz, re-plans call CasADi/IPOPT)
and the numba kernels do not release the GIL, so two threads on two cores took about as long as
one (README, "fixplan robust"). ``address`` (``tcp://HOST:8786``) connects to a running
scheduler instead: the address is checked first (:func:`check_address`), then the connection,
Dask's handshake and the scheduler's ``identity`` answer must come within ``timeout_s``
(:class:`~fixplan.settings.ClusterSettings`), else :class:`InputError` with the address and
the reason.

Every task is a module-level function of picklable arguments; its result must not depend on
which worker runs it (no shared random state).
"""

from __future__ import annotations

import ipaddress
import logging
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from fixplan.errors import InputError, shorten
from fixplan.settings import DEFAULT

DEFAULT_PORT = 8786  # Dask's scheduler port, as ``dask scheduler`` and ``Client("tcp://HOST")`` assume
_HOST_LABEL = re.compile(r"[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?")
_REASON_CHARS = 160
_PROBE_SHARE = 0.8  # of the connection time given to the probe (connect, handshake, identity)
_ADDRESS_RULE = "an address like tcp://HOST:8786 (HOST a name, an IPv4 address or an [IPv6] address in brackets)"


def check_address(address: str) -> tuple[str, int]:
    """``(host, port)`` of a scheduler address ``tcp://HOST[:PORT]``; :class:`InputError` saying what is wrong.

    Checked before any connection (Dask raises ``ValueError`` from a thread for some malformed
    addresses, and retries others until its timeout): the scheme (``tcp`` only: fixplan passes
    no TLS credentials), the host (a DNS name, an IPv4 address, or an IPv6 address in brackets),
    the port (1–65535; Dask's 8786 when left out), and nothing after it.
    """

    def bad(reason: str) -> InputError:
        return InputError(f"check_address.address expects {_ADDRESS_RULE}, got {shorten(address)}: {reason}")

    if not isinstance(address, str) or not address.isprintable() or any(c.isspace() for c in address):
        raise bad("spaces or control characters")
    scheme, sep, rest = address.partition("://")
    if not sep:
        raise bad("no scheme (tcp://)")
    if scheme != "tcp":
        raise bad(f"the scheme {shorten(scheme + '://')} is not supported (expected tcp://)")
    if rest.startswith("["):
        close = rest.find("]")
        if close < 0:
            raise bad("an IPv6 address without its closing ']'")
        host, tail = rest[1:close], rest[close + 1 :]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise bad(f"{shorten(host)} in brackets is not an IPv6 address") from None
        if tail and not tail.startswith(":"):
            raise bad(f"{shorten(tail)} after the IPv6 address (expected :PORT)")
        port_text = tail[1:] if tail else None
    else:
        host, colon, port_text_ = rest.partition(":")
        port_text = port_text_ if colon else None
        if port_text is not None and ":" in port_text:
            raise bad("more than one ':' (an IPv6 address goes in brackets: tcp://[::1]:8786)")
        if not host:
            raise bad("no host")
        labels = host.split(".")
        if len(host) > 253 or not all(_HOST_LABEL.fullmatch(label) for label in labels):
            raise bad(f"{shorten(host)} is not a host name or an IPv4 address")
        if all(label.isdigit() for label in labels):
            try:
                ipaddress.IPv4Address(host)
            except ValueError:
                raise bad(f"{shorten(host)} is not an IPv4 address") from None
    if port_text is None:
        return host, DEFAULT_PORT
    if not (port_text.isascii() and port_text.isdigit()) or len(port_text) > 5 or not 1 <= int(port_text) <= 65535:
        raise bad(f"the port {shorten(port_text)} is not a number in 1..65535")
    return host, int(port_text)


def _within(deadline_s: float, what: str, fn: Callable[[], Any]) -> Any:
    """``fn()`` run in a daemon thread; :class:`TimeoutError` if it has not finished by ``deadline_s`` (monotonic).

    A blocked connection (a peer that accepts and never answers, a name server that does not
    reply) cannot stall the command: the thread is left behind, and dies with the process.
    """
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            box["error"] = exc

    thread = threading.Thread(target=run, name=f"fixplan-{what}", daemon=True)
    thread.start()
    thread.join(max(0.0, deadline_s - time.monotonic()))
    if thread.is_alive():
        raise TimeoutError(f"no answer to the {what}")
    if "error" in box:
        raise box["error"]
    return box["value"]


_STAGES = {
    "connect": "no connection (nothing listens there, or the host cannot be reached or resolved)",
    "handshake": "connected, but no answer to Dask's handshake (a port that does not speak Dask's protocol?)",
    "identity": "connected, but no answer to an identity request (a busy or stuck scheduler?)",
}


class _NoAnswer(TimeoutError):
    """The probe ran out of time; ``stage`` says where (a key of ``_STAGES``)."""

    def __init__(self, stage: str):
        super().__init__(_STAGES[stage])
        self.stage = stage


def _identify(address: str, timeout_s: float) -> dict[str, Any]:
    """Connect (Dask's handshake included), ask ``identity``, and return the answer; all within ``timeout_s``."""
    import asyncio

    from distributed.comm import connect

    host, port = check_address(address)
    stage = "connect"

    async def probe() -> Any:
        nonlocal stage
        # a plain TCP connection first, retried while refused (a scheduler starting up): that
        # tells "nothing there" from "something there that does not answer"
        backoff_s = 0.05
        while True:
            try:
                _, writer = await asyncio.open_connection(host, port)
                break
            except OSError:
                await asyncio.sleep(backoff_s)
                backoff_s = min(2 * backoff_s, 0.5)
        writer.close()
        # then Dask's connection (its handshake's read has no timeout of its own: the caller's
        # wait_for bounds it) and one request
        stage = "handshake"
        comm = await connect(address, timeout=timeout_s)
        try:
            stage = "identity"
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    async def bounded() -> Any:
        try:
            return await asyncio.wait_for(probe(), timeout_s)
        except TimeoutError:
            raise _NoAnswer(stage) from None

    answer = asyncio.run(bounded())
    if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
        kind = answer.get("type") if isinstance(answer, dict) else type(answer).__name__
        raise ConnectionError(f"the peer is not a Dask scheduler (it answered as {shorten(repr(kind))})")
    return answer


def _reason(exc: BaseException, stage: str = "connect") -> str:
    """One printable line saying why a connection failed."""
    if isinstance(exc, _NoAnswer):
        return str(exc)
    if isinstance(exc, TimeoutError):  # asyncio's too (the same class since Python 3.11)
        return _STAGES[stage]
    if isinstance(exc, MemoryError):
        return "the peer sent data that is not Dask's protocol"
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    line = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    line = "".join(c if c.isprintable() else "?" for c in line)
    return line if len(line) <= _REASON_CHARS else line[: _REASON_CHARS - 1] + "…"


@contextmanager
def dask_client(
    address: str | None = None,
    *,
    tasks: int = 1,
    processes: bool = True,
    workers: int | None = None,
    timeout_s: float = DEFAULT.cluster.connect_timeout_s,
) -> Iterator[Any]:
    """A :class:`distributed.Client`: to ``address``, or to a local cluster closed on exit.

    The local cluster has ``workers`` (default: the cores, at most ``tasks``) single-threaded
    workers, processes unless ``processes=False``. Raises :class:`InputError` when ``address``
    is malformed (:func:`check_address`) or when a scheduler there cannot be reached, shaken
    hands with and registered with within ``timeout_s`` in all.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise InputError("dask.distributed is not installed (pip install 'dask[distributed]')") from exc
    if address is not None:
        check_address(address)
        start = time.monotonic()
        deadline = start + timeout_s
        try:
            # the probe covers what Client(timeout=...) does not: Dask's handshake read has no
            # timeout, so a port that accepts and stays silent would hang the client for ever.
            # It gets most of the time (its own bound ends first, saying at which stage); the
            # client's registration with a scheduler that answered takes a small part of the rest
            _within(deadline, "connection", lambda: _identify(address, _PROBE_SHARE * timeout_s))
            left_s = max(deadline - time.monotonic(), 0.1)
            client = _within(
                deadline, "client registration", lambda: Client(address, timeout=f"{left_s}s", set_as_default=False)
            )
        except Exception as exc:  # noqa: BLE001 - any failure to reach a scheduler is the user's input
            raise InputError(
                f"cannot reach the Dask scheduler at {address} within {timeout_s:g} s: {_reason(exc)}"
            ) from None
        try:
            yield client
        finally:
            client.close(timeout=timeout_s)
        return
    n = workers or max(1, min(os.cpu_count() or 1, tasks))
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=processes,
        dashboard_address=None,
        # the scheduler's small HTTP server (health, metrics) still starts: any free loopback port
        scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
        silence_logs=logging.ERROR,
    )
    client = Client(cluster, set_as_default=False)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def run_tasks(
    client: Any,
    fn: Callable[..., Any],
    items: Sequence[Any],
    *shared: Any,
    progress: Callable[[int, int], None] | None = None,
    name: str = "fixplan",
) -> list[Any]:
    """``[fn(item, *shared) for item in items]`` as Dask tasks, results in the order of ``items``.

    ``shared`` arguments are scattered once to every worker. ``progress(done, total)`` is called
    as tasks finish. A task's exception is re-raised here.
    """
    from distributed import as_completed

    if not items:
        return []
    shared_futures = client.scatter(list(shared), broadcast=True, hash=False) if shared else []
    futures = [
        client.submit(fn, item, *shared_futures, pure=False, key=f"{name}-{i}-{os.getpid()}-{id(items)}")
        for i, item in enumerate(items)
    ]
    index = {f.key: i for i, f in enumerate(futures)}
    results: list[Any] = [None] * len(items)
    done = 0
    try:
        for future in as_completed(futures, loop=client.loop):
            results[index[future.key]] = future.result()
            done += 1
            if progress is not None:
                progress(done, len(items))
    finally:
        for f in futures:
            f.release()
    return results


@contextmanager
def progress_bar(description: str, total: int, enabled: bool = True) -> Iterator[Callable[[int, int], None] | None]:
    """A rich progress bar on stderr (transient); yields the ``progress(done, total)`` callback."""
    if not enabled:
        yield None
        return
    from rich.console import Console
    from rich.progress import Progress

    bar = Progress(transient=True, console=Console(file=sys.stderr))
    bar.start()
    task = bar.add_task(description, total=total)

    def update(done: int, total_: int) -> None:
        bar.update(task, completed=done, total=total_)

    try:
        yield update
    finally:
        bar.stop()
