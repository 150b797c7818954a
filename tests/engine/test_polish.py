"""The step's nonsmooth Newton polish (fixplan.engine.polish): where Gauss–Seidel stalls, it solves.

The two problems below are time steps captured from the simulated load of generated free-start
plates (`fixplan generate plate-2d-free --seed 9204`, fixtures 10 and 30) before the polish
existed: the plate is pushed into the corner of a base locator and the side locator, two
contacts with μ ≈ 0.75 each, ``W`` of rank 3 for 4 rows. NSGS stalls on both; each step's
unconverged impulses let the plate sink into both contacts, and the residual grew to 0.12.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fixplan
from fixplan.engine.nsgs import solve_nsgs
from fixplan.engine.polish import _lu_solve, newton_polish
from fixplan.engine.problem import build_problem, fclib_error
from fixplan.engine.simulator import Simulator
from fixplan.engine.socp import solve_socp

CORNER_010 = dict(
    W=[
        [6.473681705211661, 4.2196150568488715, 1.7060874801428538, -1.62221321191928],
        [4.2196150568488715, 13.755546719893253, 8.266847538488543, 6.374361072365116],
        [1.706087480142854, 8.266847538488543, 6.047640139352492, 2.577300884785805],
        [-1.6222132119192798, 6.374361072365117, 2.5773008847858048, 8.951083616164876],
    ],
    q=[-0.01279704065886262, 0.005397257642536298, 0.0005538748104721573, 0.022145469490681306],
    mu=[0.756, 0.772],
    start=[0.001992835474506437, -0.0015065836187268663, 0.0020948610972209877, -0.0016172327670546025],
)
CORNER_030 = dict(
    W=[
        [0.39653163802107605, 0.06846265070683484, 0.027761626880866922, -0.382400895838418],
        [0.06846265070683484, 1.5449556600844616, 0.8598001420106355, 0.16941234777783803],
        [0.027761626880866922, 0.8598001420106355, 0.5819693590691023, 0.06869676151102447],
        [-0.382400895838418, 0.16941234777783803, 0.06869676151102448, 0.41736773081035755],
    ],
    q=[-0.009839427594118896, -0.0001320275532585306, -0.008180822444831154, 0.012634453329290453],
    mu=[0.718, 0.778],
    start=[0.01904753364581672, -0.004519180171386261, 0.021540417646291228, -0.014531098029241213],
)
TOL = 1e-6  # the haptic profile's residual


def _polish(W, q, mu, start, tol=TOL, steps=30):
    W = np.asarray(W, float)
    q = np.asarray(q, float)
    mu = np.asarray(mu, float)
    nc = mu.shape[0]
    sizes = np.full(nc, q.shape[0] // nc, dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    P = np.array(start, float)
    err, n, ok = newton_polish(W, q, mu, offsets, sizes, nc, q.shape[0], P, tol, steps)
    return P, err, n, ok


@pytest.mark.parametrize("case", [CORNER_010, CORNER_030], ids=["plate-010", "plate-030"])
def test_polish_solves_the_corner_where_gauss_seidel_stalls(case):
    W, q, mu = np.array(case["W"]), np.array(case["q"]), np.array(case["mu"])
    assert np.linalg.matrix_rank(W, tol=1e-9) == 3  # 4 rows, 3 degrees of freedom
    problem = build_problem(W, q, mu, 2)
    stalled = solve_nsgs(problem, r0=case["start"], tol=TOL, max_iter=1000)
    assert not stalled.converged and stalled.error > 1e-4  # what the step met before the polish
    P, err, _, ok = _polish(W, q, mu, stalled.reaction)
    assert ok and err <= TOL
    assert fclib_error(problem, P) == pytest.approx(err, rel=1e-9, abs=1e-12)  # the independent residual
    # the contact laws, checked directly: r in the cone, De Saxcé's modified velocity in the dual
    # cone, complementary
    u = W @ P + q
    for j in range(2):
        rn, rt = P[2 * j], P[2 * j + 1]
        un, ut = u[2 * j], u[2 * j + 1]
        scale = np.abs(P).max()
        assert abs(rt) <= mu[j] * rn + 1e-6 * scale
        un_mod = un + mu[j] * abs(ut)
        assert un_mod >= -1e-6 * np.abs(u).max() - 1e-12
        assert abs(rn * un_mod + rt * ut) <= 1e-6 * scale * (np.abs(u).max() + 1e-12)
    # the same contact velocities as an independent solver (the SOCP of Acary et al.)
    ref = solve_socp(problem, tol=1e-9)
    assert ref.error <= 1e-6
    assert np.allclose(u, np.asarray(ref.velocity), atol=1e-3 * np.abs(ref.velocity).max())


def _random_problem(seed: int, nc: int, dim: int):
    rng = np.random.default_rng(seed)
    ndof = 3 if dim == 2 else 6
    J = rng.normal(size=(nc * dim, ndof))
    W = J @ np.diag(rng.uniform(0.5, 5.0, ndof)) @ J.T  # rank ≤ ndof: often singular, like a step's
    q = rng.normal(size=nc * dim) * 0.01
    mu = rng.uniform(0.05, 1.0, nc)
    start = np.abs(rng.normal(size=nc * dim)) * 0.01
    return W, q, mu, start


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), nc=st.integers(1, 6), dim=st.sampled_from([2, 3]))
def test_polish_never_raises_the_residual(seed, nc, dim):
    W, q, mu, start = _random_problem(seed, nc, dim)
    problem = build_problem(W, q, mu, dim)
    before = fclib_error(problem, start)
    P, err, _, _ = _polish(W, q, mu, start, tol=1e-12)
    assert np.all(np.isfinite(P))
    assert err <= before * (1 + 1e-9) + 1e-12  # compiled and NumPy residuals agree to round-off
    assert fclib_error(problem, P) == pytest.approx(err, rel=1e-9, abs=1e-12)  # round-off of W P + q


def test_polish_converges_on_most_random_problems():
    # not a guarantee (a frictional contact problem may have no solution), a rate: at the haptic
    # residual 198 of these 200 (NSGS → SOCP → Newton → PROX of solve_auto: 1 of the other 2)
    solved = 0
    for seed in range(200):
        W, q, mu, start = _random_problem(seed, nc=1 + seed % 6, dim=2 + seed % 2)
        solved += _polish(W, q, mu, start, tol=TOL)[3]
    assert solved >= 195


def test_lu_solve_matches_numpy(rng):
    for n in (1, 3, 8, 24):
        M = rng.normal(size=(n, n)) + n * np.eye(n) * rng.uniform(0, 1)
        b = rng.normal(size=n)
        expected = np.linalg.solve(M, b)
        z = b.copy()
        assert _lu_solve(M.copy(), z, n)
        assert np.allclose(z, expected, rtol=1e-10, atol=1e-12)
    assert not _lu_solve(np.zeros((3, 3)), np.ones(3), 3)


@pytest.mark.parametrize("name", [None, "polygon-2d.toml"])
def test_a_step_capped_at_one_sweep_still_converges(name):
    # the wiring: with NSGS capped at one sweep, the polish carries every step of a pushed load
    from conftest import PROBLEMS

    f = fixplan.load(fixplan.default_fixture_path() if name is None else PROBLEMS / name)
    capped = Simulator(f, tolerance=1e-8, max_iterations=1)
    d = f.dimension
    push = np.r_[[2.0, 1.5, -3.0][:d], [0.05, -0.02, 0.01][: 3 if d == 3 else 1]]
    worst = 0.0
    for _ in range(200):
        capped.step(push)
        worst = max(worst, capped.last.error)
        assert capped.last.converged, capped.last
    assert worst <= 1e-8
    full = Simulator(f, tolerance=1e-8, max_iterations=5000)
    for _ in range(200):
        full.step(push)
    # the same motion as the uncapped sweep (the step's solution is unique in velocity here)
    assert np.allclose(capped.pose.p_world, full.pose.p_world, atol=1e-7)
