"""The second core, for the pure jobs the planner will likely ask for next.

The coarse search fine-plans one transition at a time, and the next one it asks for is often a
sibling of the last: another target from the same contact state and pose, once the first turned
out dearer than its estimate (a free-start box asked for four first contacts in a row, then three
ways on from {B3, S1}, each a 50 ms path program). Those jobs are pure functions of their inputs:
the same (pose, state, target) always gives the same transition. :class:`SpareCore` forks a child
that runs such jobs, one at a time, while the parent works on its own; when the parent then asks
for a job the child did (or is doing), it takes the answer instead of computing it. The answers
are the ones the parent would compute (same code, same inputs, a copy of the process): only the
wall time changes. A job the parent never asks for is wasted work on an otherwise idle core.

It forks only where :func:`fixplan.planner.policy_job.can_fork` allows (two CPUs, the main thread,
not ``FIXPLAN_POLICY_JOB=inline``) and, by default, only when a CPU is idle
(:func:`spare_cpu`; ``FIXPLAN_SPARE_CORE=on`` or ``off`` in the environment forces it either
way); otherwise it is inert: :meth:`SpareCore.offer` declines and
:meth:`SpareCore.take` finds nothing, and the parent computes everything, as before. A job that
fails in the child (an exception, a crash) is not found: the parent computes it and meets the
same exception itself. :meth:`SpareCore.close` ends the child at once (a job still running is
dropped). Messages are length-prefixed pickles over two pipes; the child writes nothing to the
terminal and leaves with ``os._exit``.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import struct
from collections.abc import Callable, Hashable
from typing import Any

from fixplan.planner.policy_job import can_fork
from fixplan.settings import DEFAULT

_HEADER = struct.Struct("<Q")
ENV = "FIXPLAN_SPARE_CORE"  # "on", "off" or "auto" (default)


def spare_cpu(idle_cpus: float | None = None) -> bool:
    """Whether to run jobs ahead on a second core here (see the module docstring)."""
    mode = os.environ.get(ENV, "auto").strip().lower()
    if mode == "off" or not can_fork():
        return False
    if mode == "on":
        return True
    need = DEFAULT.planner.spare_core_idle_cpus if idle_cpus is None else idle_cpus
    try:
        load = os.getloadavg()[0]
    except OSError:
        return False
    return (os.cpu_count() or 1) - load >= need


def _write(fd: int, payload: Any) -> None:
    data = pickle.dumps(payload, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(_HEADER.pack(len(data)) + data)
    while view:
        view = view[os.write(fd, view) :]


def _read_exactly(fd: int, size: int) -> bytes | None:
    chunks, left = [], size
    while left:
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def _read(fd: int) -> Any:
    """One message, or None when the other end closed."""
    head = _read_exactly(fd, _HEADER.size)
    if head is None:
        return None
    data = _read_exactly(fd, _HEADER.unpack(head)[0])
    return None if data is None else pickle.loads(data)


class SpareCore:
    """A forked child that runs ``run(job)`` for the jobs offered to it, one at a time.

    Parameters
    ----------
    run : callable
        A pure function of the job (the child's copy of the parent's objects at the fork).
    fork : bool, optional
        Force (True) or forbid (False) the child; default: :func:`spare_cpu`.
    """

    def __init__(self, run: Callable[[Any], Any], *, fork: bool | None = None) -> None:
        self._pid: int | None = None
        self._to_child: int | None = None
        self._from_child: int | None = None
        self._pending: Hashable | None = None  # the key the child works on
        self._busy = False
        self._done: dict[Hashable, Any] = {}
        self.offered = 0  # jobs handed to the child, and how many of them the parent took
        self.taken = 0
        if fork if fork is not None else spare_cpu():
            self._start(run)

    @property
    def active(self) -> bool:
        """Whether a child runs jobs."""
        return self._pid is not None

    def _start(self, run: Callable[[Any], Any]) -> None:
        try:
            down_r, down_w = os.pipe()
            up_r, up_w = os.pipe()
        except OSError:
            return
        try:
            pid = os.fork()
        except OSError:
            for fd in (down_r, down_w, up_r, up_w):
                os.close(fd)
            return
        if pid == 0:  # the child: jobs in, answers out, until the parent closes its end
            code = 0
            try:
                os.close(down_w)
                os.close(up_r)
                while True:
                    message = _read(down_r)
                    if message is None:
                        break
                    key, job = message
                    try:
                        answer: tuple[str, Any] = ("ok", run(job))
                    except BaseException as exc:  # noqa: BLE001 - the parent recomputes and meets it
                        answer = ("error", repr(exc))
                    _write(up_w, (key, answer))
            except BaseException:  # noqa: BLE001 - a child never returns into the parent's code
                code = 1
            finally:
                os._exit(code)
        os.close(down_r)
        os.close(up_w)
        self._pid, self._to_child, self._from_child = pid, down_w, up_r

    def _receive(self) -> None:
        """Store the child's answer to the pending job (blocks until it comes)."""
        fd = self._from_child
        if fd is None:  # closed meanwhile: nothing pending any more
            self._pending, self._busy = None, False
            return
        message = _read(fd)
        key, self._pending, self._busy = self._pending, None, False
        if message is None:  # the child died: no more jobs
            self.close()
            return
        got_key, (tag, value) = message
        if tag == "ok" and got_key == key:
            self._done[key] = value

    def _poll(self) -> None:
        """Collect the pending answer if it is ready (never blocks)."""
        if self._busy and self._from_child is not None:
            ready, _, _ = select.select([self._from_child], [], [], 0.0)
            if ready:
                self._receive()

    def offer(self, key: Hashable, job: Any) -> bool:
        """Hand ``job`` to the child if it is idle and has not done ``key``; True if it took it."""
        if self._pid is None:
            return False
        self._poll()
        if self._busy or key in self._done or self._to_child is None:
            return False
        try:
            _write(self._to_child, (key, job))
        except (OSError, pickle.PicklingError, TypeError, AttributeError):
            self.close()
            return False
        self._pending, self._busy = key, True
        self.offered += 1
        return True

    def pending(self, key: Hashable) -> bool:
        """Whether the child has done ``key`` or works on it now."""
        self._poll()
        return key in self._done or (self._busy and self._pending == key)

    def take(self, key: Hashable) -> tuple[bool, Any]:
        """``(True, answer)`` if the child did ``key`` (waiting for it if it works on it now), else ``(False, None)``."""
        if self._pid is None and not self._done:
            return False, None
        self._poll()
        if key not in self._done and self._busy and self._pending == key:
            self._receive()
        if key in self._done:
            self.taken += 1
            return True, self._done.pop(key)
        return False, None

    def close(self) -> None:
        """End the child now (a job it runs is dropped) and reap it."""
        pid, self._pid = self._pid, None
        for fd in (self._to_child, self._from_child):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._to_child = self._from_child = None
        self._busy, self._pending = False, None
        if pid is not None:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
            try:
                os.waitpid(pid, 0)
            except OSError:
                pass

    def __enter__(self) -> SpareCore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
