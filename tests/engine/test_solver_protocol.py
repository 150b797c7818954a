"""Every registered solver is a ``ContactSolver``: one signature, and the same answer to a closed form."""

import inspect

import numpy as np
import pytest

from fixplan.engine import SOLVERS, get_solver
from fixplan.engine.problem import ContactSolver, build_problem

SHARED = ("tol", "max_iter", "time_limit")  # the protocol's keywords after (problem, r0)


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_registered_solver_has_the_protocol_signature(name):
    params = inspect.signature(get_solver(name)).parameters
    first, second = list(params)[:2]
    assert (first, second) == ("problem", "r0") and params["r0"].default is None
    for key in SHARED:
        p = params[key]
        assert p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY), (name, key)
        assert p.default is not inspect.Parameter.empty, (name, key)
    protocol = inspect.signature(ContactSolver.__call__).parameters
    assert [k for k in protocol if k != "self"] == ["problem", "r0", *SHARED]


@pytest.mark.parametrize("name", sorted(SOLVERS))
def test_every_solver_presses_one_sticking_contact_to_rest(name):
    """One contact, ``W = diag(2, 1, 1)``, pushed in with ``q = (−1, 0.1, 0)``, ``μ = 0.5``: it sticks.

    Rest (``u = 0``) needs ``r = −W⁻¹ q = (0.5, −0.1, 0)``, inside the cone (0.1 ≤ 0.5 · 0.5).
    """
    problem = build_problem(np.diag([2.0, 1.0, 1.0]), [-1.0, 0.1, 0.0], [0.5], dims=3)
    sol = get_solver(name)(problem, None, tol=1e-10, max_iter=200, time_limit=30.0)
    assert sol.converged, (name, sol.extras.get("reason"))
    np.testing.assert_allclose(sol.reaction, [0.5, -0.1, 0.0], atol=1e-8)
    np.testing.assert_allclose(sol.velocity, np.zeros(3), atol=1e-8)
    assert sol.error <= 1e-10
