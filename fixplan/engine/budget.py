"""A solve's bounds: a wall-clock deadline and a cap on iterations, shared by every stage.

Every contact solver takes ``time_limit`` [s] (``None``: no limit) besides ``max_iter``. The
limit is checked between compiled chunks of work (a chunk of NSGS sweeps is sized to take about
``CHUNK_S``), before every SOCP and before every Newton factorization, so a solve ends at most
one chunk, one interior-point solve or one factorization after the deadline. A solver that hits
the limit returns its best iterate (lowest residual, not the last) with ``converged = False`` and
the reason in ``extras["reason"]``.

The deadline is a point in :func:`time.perf_counter` time, so that stages of one solve (see
:mod:`fixplan.engine.auto`) can share it: a stage gets ``budget.share(f)``, a deadline at
``f`` of the time left.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from fixplan.errors import InputError

DEFAULT_TIME_LIMIT_S = 60.0
"""Default time limit of ``solve_auto`` and ``fixplan fclib`` [s]: every FCLib solve answers within a minute."""
CHUNK_S = 0.05
"""Target wall time of one compiled chunk of sweeps between two deadline checks [s]."""


def check_time_limit(time_limit: float | None) -> float | None:
    """Validate a time limit: ``None`` or a number of seconds ``> 0`` (``inf`` allowed).

    Parameters
    ----------
    time_limit : float or None
        Seconds.

    Returns
    -------
    float or None
        The limit as a float.

    Raises
    ------
    InputError
        For NaN, zero or negative limits.
    """
    if time_limit is None:
        return None
    value = float(time_limit)
    if not value > 0:  # also catches NaN
        raise InputError(f"expected a time limit > 0 s, got {time_limit}")
    return value


@dataclass(frozen=True)
class Budget:
    """A deadline in :func:`time.perf_counter` time (``inf``: none).

    Attributes
    ----------
    deadline : float
        ``perf_counter()`` value after which work stops.
    """

    deadline: float = math.inf

    @classmethod
    def start(cls, time_limit: float | None) -> Budget:
        """A budget of ``time_limit`` seconds from now (``None``: unlimited)."""
        limit = check_time_limit(time_limit)
        return cls(math.inf if limit is None else time.perf_counter() + limit)

    def remaining_s(self) -> float:
        """Seconds left (``inf`` without a deadline, never negative)."""
        return max(self.deadline - time.perf_counter(), 0.0)

    def expired(self) -> bool:
        """Whether the deadline has passed."""
        return time.perf_counter() >= self.deadline

    def share(self, fraction: float) -> Budget:
        """A sub-budget ending after ``fraction`` of the time left (the same one when unlimited)."""
        if math.isinf(self.deadline):
            return self
        return Budget(time.perf_counter() + fraction * self.remaining_s())

    def limit_s(self) -> float | None:
        """The time left as a ``time_limit`` argument (``None`` without a deadline)."""
        if math.isinf(self.deadline):
            return None
        return max(self.remaining_s(), 1e-9)
