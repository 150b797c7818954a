"""How an engine solve ended: the one status vocabulary of the compiled kernels and the Python solvers.

Every solver of the engine stops for one of these reasons, and says it with one of these integer
codes: the compiled NSGS sweep (:func:`fixplan.engine.nsgs.nsgs_kernel`), the compiled time step
and its multi-step loops (:mod:`fixplan.engine.step`, read by the
:class:`~fixplan.engine.simulator.Simulator`), and the Python drivers of NSGS, SOCP, Newton and
PROX (their :class:`~fixplan.engine.problem.ContactSolution` carries :data:`STATUS_TEXT` of it in
``extras["status"]``). The kernels return the plain ints (numba freezes the module-level
constants into the compiled code, so this module imports no numba and the ahead-of-time
extension reads the same numbers).

A different vocabulary, on purpose with other names: the *regime* of one contact that the exact
one-contact solvers of :mod:`fixplan.engine.local` return (``OPEN``, ``STICK``, ``SLIDE``,
``FAILED``). Those are not statuses of a solve and are never compared with these codes.
"""

from __future__ import annotations

STATUS_CONVERGED = 0
"""The residual reached the tolerance."""
STATUS_MAX_ITER = 1
"""The iteration cap (sweeps, steps or rounds) came before the tolerance; for the time step: its
sweeps (and polish) ended above the tolerance."""
STATUS_NONFINITE = 2
"""A NaN or infinity appeared; the answer is the last (or best) finite iterate."""
STATUS_TIME_LIMIT = 3
"""The wall-clock limit came before the tolerance (Python drivers only)."""
STATUS_STALLED = 4
"""The residual stopped improving over the stagnation window (Python drivers only)."""

STATUS_TEXT: dict[int, str] = {
    STATUS_CONVERGED: "converged",
    STATUS_MAX_ITER: "max_iter reached before tol",
    STATUS_NONFINITE: "a non-finite value appeared; returned the best finite iterate",
    STATUS_TIME_LIMIT: "time limit reached before tol",
    STATUS_STALLED: "stalled: the residual stopped improving",
}
"""The words a solution's ``extras["status"]`` carries, by code."""
