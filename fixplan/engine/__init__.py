"""Contact engine: the time-stepping simulator, exact one-contact solvers, NSGS, SOCP, Newton and PROX solvers, FCLib I/O.

:class:`Simulator` (:mod:`.simulator`) integrates a fixture's workpiece with the compiled
Moreau–Jean step of :mod:`.step`; the rest of this package solves one contact problem
``u = W r + q`` at a time. Modules, one concept each:

- :mod:`.simulator` — the :class:`Simulator`, its trajectories and contact reports;
- :mod:`.step` — the compiled time step (2D, 3D) and the compiled multi-step loops;
- :mod:`.encode` — each shape as a kind code and parameter arrays for the kernels (no numba);
- :mod:`.detect` — gap, contact point and normal of a locator tip against each shape, and of
  the part's collision points against collision-only bodies (``[[obstacle]]``);
- :mod:`.linalg` — small dense products and inverses without BLAS;
- :mod:`.local` — the exact one-contact solvers and their closed-form shortcuts;
- :mod:`.problem` — the contact problem, its builder, its solution, the FCLib residual in NumPy
  and the helpers every solver shares (no numba);
- :mod:`.status` — how a solve ended: the one status vocabulary of kernels and solvers (no numba);
- :mod:`.nsgs` — nonsmooth Gauss–Seidel (sparse for FCLib problems, dense for the time step);
- :mod:`.residual` — the FCLib residual, compiled;
- :mod:`.socp`, :mod:`.newton`, :mod:`.auto` — the other solvers and the automatic chain;
- :mod:`.budget` — time limits and iteration caps; :mod:`.fclib` — FCLib files;
- :mod:`.outcome` — what a finished run says (no numba);

Solvers share one signature, ``solver(problem, r0=None, tol=..., max_iter=..., time_limit=...)
-> ContactSolution`` (the protocol :class:`~fixplan.engine.problem.ContactSolver`, which documents
the shared parameters once), and are looked up by name in :data:`SOLVERS` (imported lazily, so
``import fixplan.engine`` does not compile numba kernels or import Clarabel):

- ``"nsgs"``: compiled nonsmooth Gauss–Seidel (``max_iter`` = sweeps);
- ``"socp"``: successive SOCPs (Clarabel) with NSGS polishing (``max_iter`` = rounds);
- ``"nsn"``: nonsmooth (semismooth) Newton on the natural map with a line search, Siconos'
  name (``max_iter`` = steps);
- ``"prox"``: proximal point method with Newton inner solves (``max_iter`` = rounds);
- ``"auto"``: NSGS → SOCP fixed point → NSN → PROX, switching on stagnation, within a time
  limit (default 60 s; ``max_iter`` caps every stage), see :mod:`fixplan.engine.auto`;
- ``"nsgs-numpy"``: the plain NumPy reference sweep (slow; for checking).

Example
-------
>>> from fixplan.engine import build_problem, solve
>>> sol = solve(build_problem(W, q, mu=0.5, dims=3), solver="auto", tol=1e-8)  # doctest: +SKIP
>>> sol.converged, sol.error, sol.residual()  # doctest: +SKIP
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fixplan.engine.problem import ContactProblem, ContactSolution, ContactSolver

SOLVERS: dict[str, tuple[str, str]] = {
    "auto": ("fixplan.engine.auto", "solve_auto"),
    "nsgs": ("fixplan.engine.nsgs", "solve_nsgs"),
    "nsgs-numpy": ("fixplan.engine.nsgs", "solve_nsgs_reference"),
    "nsn": ("fixplan.engine.newton", "solve_newton"),
    "prox": ("fixplan.engine.newton", "solve_prox"),
    "socp": ("fixplan.engine.socp", "solve_socp"),
}
"""Solver registry: name → (module, function), imported on first use."""

_LAZY = {
    "ContactProblem": ("fixplan.engine.problem", "ContactProblem"),
    "ContactSolution": ("fixplan.engine.problem", "ContactSolution"),
    "build_problem": ("fixplan.engine.problem", "build_problem"),
    "fclib_error": ("fixplan.engine.problem", "fclib_error"),
    "solve_nsgs": ("fixplan.engine.nsgs", "solve_nsgs"),
    "solve_nsgs_reference": ("fixplan.engine.nsgs", "solve_nsgs_reference"),
    "solve_socp": ("fixplan.engine.socp", "solve_socp"),
    "solve_auto": ("fixplan.engine.auto", "solve_auto"),
    "solve_newton": ("fixplan.engine.newton", "solve_newton"),
    "solve_prox": ("fixplan.engine.newton", "solve_prox"),
    "FclibProblem": ("fixplan.engine.fclib", "FclibProblem"),
    "FclibResult": ("fixplan.engine.fclib", "FclibResult"),
    "read_fclib": ("fixplan.engine.fclib", "read_fclib"),
    "solve_fclib_file": ("fixplan.engine.fclib", "solve_fclib_file"),
    "solve_cone": ("fixplan.engine.local", "solve_cone"),
    "solve_coulomb_2d": ("fixplan.engine.local", "solve_coulomb_2d"),
    "solve_coulomb_3d": ("fixplan.engine.local", "solve_coulomb_3d"),
    "solve_soft_finger": ("fixplan.engine.local", "solve_soft_finger"),
    "project_cone": ("fixplan.engine.local", "project_cone"),
    "law_violation": ("fixplan.engine.local", "law_violation"),
    "Simulator": ("fixplan.engine.simulator", "Simulator"),
    "WrenchSchedule": ("fixplan.engine.simulator", "WrenchSchedule"),
    "BodyState": ("fixplan.engine.simulator", "BodyState"),
}

__all__ = sorted([*_LAZY, "SOLVERS", "get_solver", "solve"])


def get_solver(name: str) -> ContactSolver:
    """The solver registered under ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`SOLVERS`.

    Returns
    -------
    ContactSolver
        ``solver(problem, r0=None, tol=..., max_iter=..., time_limit=...) -> ContactSolution``.

    Raises
    ------
    InputError
        For an unknown name; the message lists the known ones.
    """
    from fixplan.errors import InputError

    try:
        module_name, attr = SOLVERS[name]
    except (KeyError, TypeError):
        known = ", ".join(sorted(SOLVERS))
        raise InputError(f"unknown contact solver {name!r}; known solvers: {known}") from None
    solver: ContactSolver = getattr(import_module(module_name), attr)
    return solver


def solve(problem: ContactProblem, solver: str = "auto", **options: Any) -> ContactSolution:
    """Solve a contact problem with a solver chosen by name.

    Parameters
    ----------
    problem : ContactProblem
        From :func:`build_problem`.
    solver : str
        A key of :data:`SOLVERS`.
    **options
        ``r0``, ``tol``, ``max_iter`` and solver-specific options.

    Returns
    -------
    ContactSolution
        The answer and its residual.
    """
    return get_solver(solver)(problem, **options)


def __getattr__(name: str) -> Any:
    try:
        module_name, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'fixplan.engine' has no attribute {name!r}") from None
    value = getattr(import_module(module_name), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
