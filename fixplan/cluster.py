"""Running independent tasks on a Dask cluster: in-process local workers, or a scheduler's address.

``fixplan robust`` (one task per perturbed world) and ``fixplan solve --batch`` (one task per
fixture file) both go through :func:`dask_client` and :func:`run_tasks`.

Local default: a :class:`distributed.LocalCluster` of worker *processes*, one thread each, as
many as there are cores (at most one per task). Threads were measured and lose: a verification
is mostly Python (the executor re-solves its cone program at 200 Hz, re-plans call CasADi/IPOPT)
and the numba kernels do not release the GIL, so two threads on two cores took about as long as
one (README, "fixplan robust"). ``address`` (``tcp://HOST:8786``) connects to a running
scheduler instead, failing within ``timeout_s`` with the address and the reason.

Every task is a module-level function of picklable arguments; its result must not depend on
which worker runs it (no shared random state).
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

from fixplan.errors import InputError

CONNECT_TIMEOUT_S = 10.0


def _check_address(address: str) -> None:
    scheme, sep, rest = address.partition("://")
    if not sep or scheme not in ("tcp", "tls", "inproc", "ws", "wss") or not rest:
        raise InputError(f"--scheduler expects an address like tcp://HOST:8786, got {address!r}")


@contextmanager
def dask_client(
    address: str | None = None,
    *,
    tasks: int = 1,
    processes: bool = True,
    workers: int | None = None,
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> Iterator[Any]:
    """A :class:`distributed.Client`: to ``address``, or to a local cluster closed on exit.

    The local cluster has ``workers`` (default: the cores, at most ``tasks``) single-threaded
    workers, processes unless ``processes=False``. Raises :class:`InputError` when the scheduler
    at ``address`` cannot be reached within ``timeout_s``.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise InputError("dask.distributed is not installed (pip install 'dask[distributed]')") from exc
    if address is not None:
        _check_address(address)
        try:
            client = Client(address, timeout=f"{timeout_s}s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InputError(f"cannot reach the Dask scheduler at {address} within {timeout_s:g} s: {reason}") from None
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
