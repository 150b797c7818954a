"""Wedging: whether the contacts can hold a self-equilibrated set of forces.

A contact set *wedges* when nonzero contact forces inside the friction cones balance each
other with no applied wrench: ``∃ f ∈ K, f ≠ 0, Jᵀ f = 0``. Whitney's peg in a hole wedges at
two-point contact exactly when the line joining the contacts lies inside both friction cones,
i.e. ``l < 2 r μ`` for horizontal wall normals (depth ``l``, peg diameter ``2r``).

Decided by one SOCP: maximise the total normal force subject to ``Jᵀ f = 0``, ``f ∈ K`` and
``Σ f_n ≤ 1``; the optimum is positive exactly when the contacts can wedge.
"""

from __future__ import annotations

import numpy as np

from fixplan.errors import SolverError
from fixplan.jamming.backends import ClarabelProgram
from fixplan.jamming.programs import ConeProgram, force_layout
from fixplan.kinematics import ContactSet
from fixplan.settings import DEFAULT_TOLERANCES


def wedge_program(cs: ContactSet) -> ConeProgram:
    """``min −Σ f_n  s.t.  Jᵀ S f = 0, 1 − Σ f_n ≥ 0, f ∈ K``."""
    lay = force_layout(cs)
    nf = lay.nf
    c = np.zeros(nf)
    c[lay.normal_index] = -1.0
    B = cs.J.T @ lay.S
    ones = np.zeros((1, nf))
    ones[0, lay.normal_index] = 1.0
    A = np.vstack([B, ones, -lay.cone_rows])
    b = np.concatenate([np.zeros(cs.ndof), [1.0], np.zeros(lay.cone_rows.shape[0])])
    cones = (("zero", cs.ndof), ("nonneg", 1), *lay.cones)
    return ConeProgram(c, A, b, cones, "wedge", nf)


def wedge_force(cs: ContactSet) -> float | None:
    """Largest total normal force (out of 1) the contacts can hold with no applied wrench.

    None when the program was not solved (the force is then unknown, not 0).
    """
    prog = wedge_program(cs)
    sol = ClarabelProgram(prog).solve(prog.b)
    return max(0.0, -sol.value) if sol.solved else None


def can_wedge(cs: ContactSet, tol: float | None = None) -> bool:
    """True when the contacts can hold nonzero self-equilibrated forces (they wedge).

    ``tol`` (default :attr:`fixplan.settings.Tolerances.wedge_force`) is the least total normal
    force, out of 1, that counts; :class:`SolverError` when the program could not be solved.
    """
    force = wedge_force(cs)
    if force is None:
        raise SolverError("the wedging program was not solved: cannot say whether the contacts wedge")
    return force > (DEFAULT_TOLERANCES.wedge_force if tol is None else tol)
