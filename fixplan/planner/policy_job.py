"""The policy built on the second core while the plan's simulated load runs on the first.

:func:`~fixplan.planner.policy.build_policy` and :func:`~fixplan.planner.verify.verify` are
independent until the executor meets a state the plan does not expect: only then does it consult
the policy. ``solve`` therefore starts the policy in a forked child process, hands the executor a
:class:`PendingPolicy` and runs the verification; the first consultation (or the end of the
verification) waits for the child. The answer is the same policy, computed by the same code from
the same inputs (the child is a copy of the process at the fork), so the result is identical to
building it first; only the wall time changes (a 3D solve spent a sixth of it in the policy).

When there is nothing to gain or forking is not safe the policy is built in this process, before
the verification, as before: with one CPU, on a platform without ``fork``, outside the main
thread (a Dask worker's task runs in a thread pool: its process has threads that hold locks a
child would inherit), or with ``FIXPLAN_POLICY_JOB=inline`` in the environment. A child that fails
in any way (an exception, a crash, an unreadable answer) is replaced by the in-process build, and
the build's own exception, if any, is raised there.

The child writes nothing to the terminal (the planner's progress callback is dropped in it) and
leaves with ``os._exit``: no ``atexit`` handler, no buffered output of the parent is run twice.
"""

from __future__ import annotations

import os
import pickle
import threading
from collections.abc import Callable
from typing import Any

from fixplan.planner.policy import Policy

ENV = "FIXPLAN_POLICY_JOB"


def can_fork() -> bool:
    """Whether a forked child may build the policy here (see the module docstring)."""
    if os.environ.get(ENV, "").strip().lower() == "inline":
        return False
    if not hasattr(os, "fork") or (os.cpu_count() or 1) < 2:
        return False
    return threading.current_thread() is threading.main_thread()


class PendingPolicy:
    """A policy being built: attribute access waits for it (:meth:`result`), then delegates."""

    def __init__(
        self,
        build: Callable[[], tuple[Policy, dict[Any, Any]]],
        *,
        fork: bool | None = None,
        in_child: Callable[[], None] | None = None,
    ) -> None:
        self._build = build
        self._in_child = in_child
        self._policy: Policy | None = None
        self._memo: dict[Any, Any] = {}
        self._pid: int | None = None
        self._fd: int | None = None
        if fork if fork is not None else can_fork():
            self._start()
        if self._pid is None:
            self._policy, self._memo = build()

    def _start(self) -> None:
        try:
            r, w = os.pipe()
        except OSError:
            return
        try:
            pid = os.fork()
        except OSError:
            os.close(r)
            os.close(w)
            return
        if pid == 0:  # the child: build, send, leave without running the parent's exit handlers
            code = 0
            try:
                os.close(r)
                try:
                    if self._in_child is not None:
                        self._in_child()
                    payload = pickle.dumps(("ok", self._build()), protocol=pickle.HIGHEST_PROTOCOL)
                except BaseException as exc:  # noqa: BLE001 - reported to the parent, which rebuilds
                    payload = pickle.dumps(("error", repr(exc)))
                with os.fdopen(w, "wb") as out:
                    out.write(payload)
            except BaseException:  # noqa: BLE001 - a child never returns into the parent's code
                code = 1
            finally:
                os._exit(code)
        os.close(w)
        self._pid, self._fd = pid, r

    @property
    def started_in_child(self) -> bool:
        """Whether a child process builds (or built) the policy."""
        return self._pid is not None

    def result(self) -> Policy:
        """The policy (waits for the child; builds it here when the child failed)."""
        if self._policy is None:
            self._policy, self._memo = self._collect()
        return self._policy

    @property
    def memo(self) -> dict[Any, Any]:
        """The build's memo of representative poses and checked pushes (after :meth:`result`)."""
        self.result()
        return self._memo

    def _collect(self) -> tuple[Policy, dict[Any, Any]]:
        data = b""
        fd, pid = self._fd, self._pid
        self._fd = self._pid = None
        if fd is not None:
            with os.fdopen(fd, "rb") as src:
                data = src.read()
        if pid is not None:
            os.waitpid(pid, 0)
        try:
            tag, value = pickle.loads(data)
            if tag == "ok":
                policy, memo = value
                if isinstance(policy, Policy) and isinstance(memo, dict):
                    return policy, memo
        except Exception:  # noqa: BLE001 - any unreadable answer: build it here instead
            pass
        return self._build()

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.result(), name)

    def __del__(self) -> None:
        # a policy never asked for: the child is still reaped (no zombie)
        fd, pid = getattr(self, "_fd", None), getattr(self, "_pid", None)
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
        if pid is not None:
            try:
                os.waitpid(pid, 0)
            except OSError:
                pass


__all__ = ["ENV", "PendingPolicy", "can_fork"]
