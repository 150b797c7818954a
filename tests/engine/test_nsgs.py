"""NSGS and the robust SOCP solver on ``u = W r + q``: residual, agreement, physics, safety."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fixplan.engine import SOLVERS, get_solver, solve
from fixplan.engine.auto import solve_auto
from fixplan.engine.local import law_violation
from fixplan.engine.nsgs import solve_nsgs, solve_nsgs_reference
from fixplan.engine.problem import build_problem, fclib_error
from fixplan.engine.socp import solve_socp
from fixplan.errors import InputError

# --------------------------------------------------------------------------- problem builders


def box_stack(
    n_boxes: int,
    mass_ratio: float = 1.0,
    mu: float = 0.5,
    v0_scale: float = 0.0,
    f_scale: float = 0.0,
    seed: int = 0,
    h: float = 1e-3,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Delassus data of a stack of unit boxes (4 corner contacts per interface).

    Box k has mass ``mass_ratio**k`` [kg]; gravity plus random horizontal forces
    (``f_scale`` × weight) and random initial velocities (``v0_scale`` [m/s]); time step ``h``.
    The corner contacts are redundant, so ``W = J M⁻¹ Jᵀ`` has rank 6·n_boxes of 12·n_boxes.
    """
    rng = np.random.default_rng(seed)
    side, height = 1.0, 0.5
    nd = 6 * n_boxes
    Minv = np.zeros((nd, nd))
    f = np.zeros(nd)
    v0 = np.zeros(nd)
    for k in range(n_boxes):
        m = mass_ratio**k
        inertia = m / 12 * np.array([side**2 + height**2, side**2 + height**2, 2 * side**2])
        Minv[6 * k : 6 * k + 3, 6 * k : 6 * k + 3] = np.eye(3) / m
        Minv[6 * k + 3 : 6 * k + 6, 6 * k + 3 : 6 * k + 6] = np.diag(1 / inertia)
        f[6 * k + 2] = -9.81 * m
        f[6 * k : 6 * k + 2] += f_scale * 9.81 * m * rng.standard_normal(2)
        v0[6 * k : 6 * k + 2] = v0_scale * rng.standard_normal(2)
        v0[6 * k + 2] = -v0_scale * abs(rng.standard_normal())
    rows = []
    frame = (np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    for k in range(n_boxes):
        for sx in (-1, 1):
            for sy in (-1, 1):
                p = np.array([sx * side / 2, sy * side / 2, k * height])
                for d in frame:  # (n, t1, t2): n from the lower body into box k
                    row = np.zeros(nd)
                    c_up = np.array([0, 0, (k + 0.5) * height])
                    row[6 * k : 6 * k + 3] = d
                    row[6 * k + 3 : 6 * k + 6] = np.cross(p - c_up, d)
                    if k > 0:
                        c_lo = np.array([0, 0, (k - 0.5) * height])
                        row[6 * (k - 1) : 6 * (k - 1) + 3] -= d
                        row[6 * (k - 1) + 3 : 6 * k] -= np.cross(p - c_lo, d)
                    rows.append(row)
    J = np.array(rows)
    return J @ Minv @ J.T, J @ (v0 + h * Minv @ f), np.full(len(rows) // 3, mu)


def random_problem(rng, dims, mu_range=(0.1, 0.8), cond=None):
    """Random SPD problem with the given contact dimensions (soft fingers get e_r = 0.05 m)."""
    m = int(np.sum(dims))
    Q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    ev = rng.uniform(0.5, 2.0, m) if cond is None else np.logspace(0, -np.log10(cond), m)
    W = (Q * ev) @ Q.T
    q = rng.standard_normal(m)
    mu = rng.uniform(*mu_range, len(dims))
    return build_problem(W, q, mu, dims=np.array(dims), torsion_radius=0.05)


def assert_law_per_contact(problem, reaction, tol):
    """Every contact's one-contact law holds at the solution (given the others)."""
    W = problem.W.toarray()
    u = W @ reaction + problem.q
    for j in range(problem.n_contacts):
        o, d = problem.offsets[j], problem.dims[j]
        rows = slice(o, o + d)
        alpha = u[rows] - W[rows, rows] @ reaction[rows]
        e_r = problem.torsion_radius[j] if d == 4 else None
        assert law_violation(W[rows, rows], alpha, problem.mu[j], reaction[rows], e_r) <= tol


# --------------------------------------------------------------------------- residual formula


def test_residual_on_hand_made_single_contact():
    # W = I, q = (−1, 2, 0), μ = 0.5. Closed form: slide, r* = (1, −0.5, 0), u* = (0, 1.5, 0).
    problem = build_problem(np.eye(3), [-1.0, 2.0, 0.0], 0.5)
    # r = 0: ũ = (0, 2, 0), x = (0, −2, 0) → Proj = (0.8, −0.4, 0); err = √0.8 / ‖q‖ = 0.4
    assert fclib_error(problem, np.zeros(3)) == pytest.approx(0.4, abs=1e-15)
    # r = (3, 0, 0): u = (2, 2, 0), ũ = (3, 2, 0), x = (0, −2, 0); r − Proj = (2.2, 0.4, 0)
    # and the denominator is ‖r‖ = 3 (> ‖u‖ = 2√2 > ‖q‖ = √5): err = √5 / 3
    assert fclib_error(problem, np.array([3.0, 0.0, 0.0])) == pytest.approx(math.sqrt(5) / 3)
    assert fclib_error(problem, np.array([1.0, -0.5, 0.0])) == 0.0
    sol = solve_nsgs(problem, tol=1e-14)
    np.testing.assert_allclose(sol.reaction, [1.0, -0.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(sol.velocity, [0.0, 1.5, 0.0], atol=1e-15)
    assert sol.converged and sol.iterations == 1 and sol.error <= 1e-15
    # the compiled residual of the starting point is the same number
    cold = solve_nsgs(problem, tol=1e-14, max_iter=0)
    assert cold.error == pytest.approx(0.4, abs=1e-15) and not cold.converged


def test_residual_is_zero_when_q_is_zero():
    problem = build_problem(np.eye(6), np.zeros(6), 0.3)
    sol = solve_nsgs(problem)
    assert sol.converged and sol.iterations == 0 and sol.error == 0.0


def test_solution_recomputes_its_residual_and_is_frozen(rng):
    problem = random_problem(rng, [3, 3, 2, 4, 3])
    sol = solve_nsgs(problem, tol=1e-10)
    assert sol.converged
    assert sol.residual() == pytest.approx(sol.error, rel=1e-9, abs=1e-15)
    # against other data the residual is recomputed, not copied
    assert sol.residual(q=problem.q + 1.0) > 1e-3
    with pytest.raises(dataclasses.FrozenInstanceError):
        sol.error = 0.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        sol.reaction[0] = 1.0


# --------------------------------------------------------------------------- numba vs NumPy


@pytest.mark.parametrize("omega", [1.0, 0.7, 1.3])
def test_compiled_sweep_matches_numpy_reference(rng, omega):
    problem = random_problem(rng, [3, 2, 4, 3, 3, 4, 2, 3])
    r0 = rng.standard_normal(problem.size) * 0.1
    # the same number of sweeps from the same start: the same iterate up to rounding
    fast = solve_nsgs(problem, r0=r0, tol=0.0, max_iter=7, omega=omega)
    slow = solve_nsgs_reference(problem, r0=r0, tol=0.0, max_iter=7, omega=omega)
    assert fast.iterations == slow.iterations == 7
    scale = np.linalg.norm(slow.reaction)
    assert np.max(np.abs(fast.reaction - slow.reaction)) <= 1e-12 * scale
    # residuals near convergence are differences of close numbers: compare them absolutely
    np.testing.assert_allclose(
        fast.extras["history"], slow.extras["history"], rtol=0, atol=1e-14 * slow.extras["history"][0]
    )
    # and to convergence
    fast = solve_nsgs(problem, tol=1e-13, max_iter=2000, omega=omega)
    slow = solve_nsgs_reference(problem, tol=1e-13, max_iter=2000, omega=omega)
    assert fast.converged and slow.converged
    assert abs(fast.iterations - slow.iterations) <= 1
    assert np.max(np.abs(fast.reaction - slow.reaction)) <= 1e-12 * np.linalg.norm(slow.reaction)


# --------------------------------------------------------------------------- physics


def test_mixed_dimensions_satisfy_every_law(rng):
    problem = random_problem(rng, [4, 3, 2, 4, 4, 3, 2], mu_range=(0.0, 1.5))
    sol = solve_nsgs(problem, tol=1e-13, max_iter=5000)
    assert sol.converged
    assert_law_per_contact(problem, sol.reaction, 1e-10)
    # soft fingers: P_t1² + P_t2² + P_s²/e_r² ≤ μ² P_n²
    for j in np.flatnonzero(problem.dims == 4):
        o = problem.offsets[j]
        pn, pt1, pt2, ps = sol.reaction[o : o + 4]
        e_r, mu = problem.torsion_radius[j], problem.mu[j]
        assert pt1**2 + pt2**2 + (ps / e_r) ** 2 <= (mu * pn) ** 2 * (1 + 1e-12) + 1e-300


def test_box_at_rest_on_four_corners_holds_its_weight():
    W, q, mu = box_stack(1, mu=0.5)
    sol = solve_nsgs(build_problem(W, q, mu), tol=1e-12, max_iter=5000)
    assert sol.converged
    h, m, g = 1e-3, 1.0, 9.81
    # impulses [N·s] carry the weight over the step; the four corners share it in some way
    # (W has rank 6 of 12: the split is not unique) but friction has no net resultant
    assert sol.reaction[0::3].sum() == pytest.approx(m * g * h, rel=1e-9)
    assert abs(sol.reaction[1::3].sum()) <= 1e-12 and abs(sol.reaction[2::3].sum()) <= 1e-12
    assert np.all(sol.reaction[0::3] >= 0.0)
    assert np.max(np.abs(sol.velocity)) <= 1e-9  # at rest


def test_warm_start_reduces_iterations():
    W, q, mu = box_stack(3, mu=0.3, v0_scale=0.01, f_scale=1.0, seed=3)
    previous = solve_nsgs(build_problem(W, q, mu), tol=1e-10, max_iter=20000)
    assert previous.converged
    # the next time step sees a slightly different free velocity (q must stay in range(J):
    # the stack is rebuilt with a longer step, not perturbed at random); the closer the
    # previous answer, the fewer sweeps from it
    warm_iterations = []
    for h in (1.01e-3, 1.001e-3, 1.0001e-3):
        W, q_next, mu = box_stack(3, mu=0.3, v0_scale=0.01, f_scale=1.0, seed=3, h=h)
        nxt = build_problem(W, q_next, mu)
        cold = solve_nsgs(nxt, tol=1e-10, max_iter=20000)
        warm = solve_nsgs(nxt, r0=previous.reaction, tol=1e-10, max_iter=20000)
        assert cold.converged and warm.converged
        assert warm.iterations < 0.8 * cold.iterations, (warm.iterations, cold.iterations)
        warm_iterations.append(warm.iterations)
    assert warm_iterations == sorted(warm_iterations, reverse=True)
    assert warm_iterations[-1] < 0.6 * cold.iterations


# --------------------------------------------------------------------------- no NaN ever


def test_zero_and_singular_w_stay_finite():
    # W = 0: no contact can act; the solver reports failure, never NaN
    problem = build_problem(np.zeros((6, 6)), [-1.0, 0.5, 0.0, 0.3, 0.0, 0.0], 0.5)
    sol = solve_nsgs(problem, max_iter=50)
    assert not sol.converged and np.all(np.isfinite(sol.reaction))
    assert "reason" in sol.extras and sol.extras["local_failures"] > 0
    # duplicated contact (two identical rows of J): W singular, still solved
    J = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    J = np.vstack([J, J])
    W = J @ J.T
    problem = build_problem(W, J @ np.array([0.1, 0.0, -1.0]), 0.3)
    sol = solve_nsgs(problem, tol=1e-12)
    assert sol.converged and np.all(np.isfinite(sol.reaction))


def test_blow_up_stops_with_the_last_finite_iterate():
    # a (non-physical, indefinite) W with a 1e200 coupling makes the impulses explode
    W = np.eye(6)
    W[0, 3] = W[3, 0] = -1e200
    problem = build_problem(W, [-1.0, 0.0, 0.0, -1.0, 0.0, 0.0], 0.5)
    sol = solve_nsgs(problem, max_iter=50)
    assert not sol.converged and sol.iterations == 1
    assert "non-finite" in sol.extras["status"] and "NaN" in sol.extras["reason"]
    np.testing.assert_array_equal(sol.reaction, 0.0)  # the last finite iterate: the start
    assert np.all(np.isfinite(sol.velocity)) and math.isfinite(sol.error)


def test_overflowing_start_reports_inf_not_nan():
    problem = build_problem(np.eye(6) * 1e300, [1.0, 0.0, 0.0, 1.0, 0.0, 0.0], 0.5)
    sol = solve_nsgs(problem, r0=[1e10, 0, 0, 0, 0, 0], max_iter=5)
    assert not sol.converged and sol.error == math.inf
    assert not np.any(np.isnan(sol.velocity)) and not np.any(np.isnan(sol.reaction))


# --------------------------------------------------------------------------- the robust solver


def test_socp_solves_a_stack_where_nsgs_stalls():
    # 8 boxes, mass ratio 10 between neighbours: W has rank 48 of 96 and NSGS crawls
    W, q, mu = box_stack(8, mass_ratio=10.0, mu=0.3, v0_scale=0.01, seed=8)
    problem = build_problem(W, q, mu)
    stalled = solve_nsgs(problem, tol=1e-8, max_iter=2000)
    assert not stalled.converged and stalled.error > 1e-6
    robust = solve_socp(problem, tol=1e-8)
    assert robust.converged and robust.error <= 1e-8
    assert robust.residual() <= 1e-8
    auto = solve_auto(problem, tol=1e-8)
    assert auto.converged and auto.solver == "auto(nsgs+socp)"


def test_socp_agrees_with_nsgs_on_mixed_cones(rng):
    # μ = 0 contacts (r_n ≥ 0, r_t = 0), planar, 3D and soft-finger cones in one problem
    problem = random_problem(rng, [3, 2, 4, 3, 3, 2, 4], mu_range=(0.0, 0.6))
    problem = build_problem(problem.W, problem.q, np.r_[0.0, problem.mu[1:]], problem.dims, 0.05)
    ref = solve_nsgs(problem, tol=1e-12, max_iter=5000)
    sol = solve_socp(problem, tol=1e-10)
    assert ref.converged and sol.converged
    np.testing.assert_allclose(sol.reaction, ref.reaction, atol=1e-8 * np.linalg.norm(ref.reaction))


def test_auto_takes_nsgs_alone_on_easy_problems(rng):
    sol = solve(random_problem(rng, [3, 3, 3]), solver="auto", tol=1e-10)
    assert sol.converged and sol.solver == "auto(nsgs)"


# --------------------------------------------------------------------------- API errors


def test_unknown_solver_lists_the_known_ones():
    with pytest.raises(InputError, match="known solvers: auto, nsgs"):
        get_solver("pgs")
    assert {"auto", "nsgs", "socp", "nsgs-numpy"} <= set(SOLVERS)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"W": np.eye(4), "q": np.zeros(3)}, "shape"),
        ({"W": np.eye(3), "q": np.zeros(3), "mu": -0.1}, "μ ≥ 0"),
        ({"W": np.eye(4), "q": np.zeros(4), "dims": 4}, "torsion_radius"),
        ({"W": np.eye(5), "q": np.zeros(5), "dims": [2, 2]}, "sum to 4"),
        ({"W": np.eye(3), "q": [np.nan, 0, 0]}, "finite"),
    ],
)
def test_build_problem_rejects_bad_input(kwargs, match):
    args = {"mu": 0.5, **kwargs}
    with pytest.raises(InputError, match=match):
        build_problem(**args)


def test_bad_settings_raise():
    problem = build_problem(np.eye(3), [-1.0, 0.0, 0.0], 0.5)
    with pytest.raises(InputError, match="ω"):
        solve_nsgs(problem, omega=2.5)
    with pytest.raises(InputError, match="r0"):
        solve_nsgs(problem, r0=np.zeros(4))
