"""One-contact solvers: the contact law holds exactly, closed forms, degenerate data."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fixplan.engine.local import (
    FAILED,
    OPEN,
    SLIDE,
    STICK,
    law_violation,
    project_cone,
    solve_cone,
    solve_coulomb_2d,
    solve_coulomb_3d,
    solve_soft_finger,
)

LAW_TOL = 1e-12


def random_spd(rng: np.random.Generator, d: int, cond: float | None = None) -> np.ndarray:
    """Random SPD matrix; with ``cond`` its eigenvalues span [1/cond, 1] (log-uniformly)."""
    Q, _ = np.linalg.qr(rng.standard_normal((d, d)))
    if cond is None:
        ev = rng.uniform(0.1, 3.0, d)
    else:
        ev = np.logspace(0.0, -np.log10(cond), d)
        rng.shuffle(ev)
    return (Q * ev) @ Q.T


def solve_any(W, alpha, mu, e_r=None):
    d = alpha.shape[0]
    if d == 2:
        return solve_coulomb_2d(W, alpha, mu)
    if d == 3:
        return solve_coulomb_3d(W, alpha, mu)
    return solve_soft_finger(W, alpha, mu, e_r)


@pytest.mark.parametrize("d", [2, 3, 4])
@pytest.mark.parametrize("cond", [None, 1e6, 1e10])
def test_law_holds_on_random_spd(rng, d, cond):
    statuses = set()
    for trial in range(400):
        W = random_spd(rng, d, cond)
        alpha = rng.standard_normal(d) * 10.0 ** rng.uniform(-3, 3)
        mu = [0.0, 0.3, 2.0, rng.uniform(0.0, 5.0)][trial % 4]
        e_r = rng.uniform(1e-3, 0.5) if d == 4 else None
        P, status, _ = solve_any(W, alpha, mu, e_r)
        statuses.add(status)
        assert status != FAILED
        assert np.all(np.isfinite(P))
        assert law_violation(W, alpha, mu, P, e_r) <= LAW_TOL, (W, alpha, mu, P)
    assert {OPEN, STICK, SLIDE} <= statuses  # every regime was exercised


# Inputs keep a dynamic range of 1e150 (tinier entries are flushed to 0): the impulse scales
# like the smallest entries, and an answer that falls out of the normal float range cannot carry
# the 1e-12 relative accuracy asked here (the solver stays finite on such data).
def _flush(x: float) -> float:
    return 0.0 if abs(x) < 1e-150 else x


@settings(max_examples=300, deadline=None)
@given(
    d=st.sampled_from([2, 3, 4]),
    entries=st.lists(st.floats(-10, 10, allow_subnormal=False).map(_flush), min_size=16, max_size=16),
    alpha_in=st.lists(st.floats(-1e3, 1e3, allow_subnormal=False).map(_flush), min_size=4, max_size=4),
    mu=st.floats(0.0, 3.0, allow_subnormal=False).map(_flush),
    shift=st.floats(1e-6, 1e2),
)
def test_law_holds_hypothesis(d, entries, alpha_in, mu, shift):
    B = np.array(entries).reshape(4, 4)[:d, :d]
    W = B @ B.T + shift * np.eye(d)
    alpha = np.array(alpha_in[:d])
    P, status, _ = solve_any(W, alpha, mu, 0.05)
    assert status != FAILED
    assert law_violation(W, alpha, mu, P, 0.05 if d == 4 else None) <= LAW_TOL


def test_nonsymmetric_block_with_positive_definite_symmetric_part(rng):
    # FCLib's Capsules problem has slightly non-symmetric diagonal blocks
    for _ in range(300):
        W = random_spd(rng, 3) + 0.3 * (lambda S: S - S.T)(rng.standard_normal((3, 3)))
        alpha = rng.standard_normal(3)
        P, status, _ = solve_coulomb_3d(W, alpha, 0.8)
        assert status != FAILED
        assert law_violation(W, alpha, 0.8, P) <= LAW_TOL


def test_closed_forms_identity_block():
    W = np.eye(3)
    # open: approaching velocity positive → no impulse
    P, status, _ = solve_coulomb_3d(W, np.array([0.2, 1.0, -1.0]), 0.5)
    assert status == OPEN and np.all(P == 0.0)
    # stick: ‖α_t‖ ≤ μ(−α_n) → P = −α
    P, status, _ = solve_coulomb_3d(W, np.array([-1.0, 0.3, -0.2]), 0.5)
    assert status == STICK
    np.testing.assert_allclose(P, [1.0, -0.3, 0.2], rtol=0, atol=1e-15)
    # slide: P_n = −α_n, P_t = −μ P_n α_t/‖α_t‖, u_t = α_t (1 − μP_n/‖α_t‖)
    alpha = np.array([-1.0, 1.2, 1.6])  # ‖α_t‖ = 2 > μ P_n = 0.5
    P, status, _ = solve_coulomb_3d(W, alpha, 0.5)
    assert status == SLIDE
    np.testing.assert_allclose(P, [1.0, -0.3, -0.4], rtol=0, atol=1e-15)
    # frictionless: only the normal impulse
    P, status, _ = solve_coulomb_3d(W, alpha, 0.0)
    np.testing.assert_allclose(P, [1.0, 0.0, 0.0], rtol=0, atol=0)


def test_2d_closed_form_slide_coupled_block():
    # W_nt ≠ 0: sliding direction s = sign(u_t), P_n = −α_n/(W_nn − s μ W_nt)
    W = np.array([[2.0, 0.5], [0.5, 1.0]])
    alpha = np.array([-1.0, 3.0])
    mu = 0.4
    P, status, _ = solve_coulomb_2d(W, alpha, mu)
    pn = 1.0 / (2.0 - 0.4 * 0.5)
    assert status == SLIDE
    np.testing.assert_allclose(P, [pn, -mu * pn], rtol=1e-15)
    u = W @ P + alpha
    assert abs(u[0]) < 1e-15 and u[1] > 0


def test_2d_closed_form_matches_general_root_find(rng):
    for _ in range(500):
        W = random_spd(rng, 2)
        alpha = rng.standard_normal(2)
        mu = rng.uniform(0.0, 2.0)
        P2, s2, _ = solve_coulomb_2d(W, alpha, mu)
        Pg, sg, _ = solve_cone(W, alpha, mu)
        assert s2 == sg
        np.testing.assert_allclose(P2, Pg, rtol=1e-10, atol=1e-12 * np.linalg.norm(P2))


def test_soft_finger_spin_down_closed_form():
    # pure spin about the normal, decoupled block: the torsional friction stops the spin if
    # |ω|/W_ss ≤ e_r μ P_n, else it saturates at P_s = −sign(ω) e_r μ P_n
    W = np.diag([2.0, 1.0, 1.0, 4.0])
    e_r, mu, a = 0.05, 0.5, 1.0
    pn = a / 2.0
    stop = np.array([-a, 0.0, 0.0, 0.04])  # needs |P_s| = 0.01 ≤ e_r μ P_n = 0.0125
    P, status, _ = solve_soft_finger(W, stop, mu, e_r)
    assert status == STICK
    np.testing.assert_allclose(P, [pn, 0.0, 0.0, -0.01], atol=1e-15)
    spin = np.array([-a, 0.0, 0.0, 1.0])
    P, status, _ = solve_soft_finger(W, spin, mu, e_r)
    assert status == SLIDE
    np.testing.assert_allclose(P, [pn, 0.0, 0.0, -e_r * mu * pn], atol=1e-15)


def test_soft_finger_impulse_inside_ellipsoid(rng):
    for _ in range(300):
        W = random_spd(rng, 4)
        alpha = rng.standard_normal(4)
        mu, e_r = rng.uniform(0.1, 2.0), rng.uniform(1e-3, 0.2)
        P, _, _ = solve_soft_finger(W, alpha, mu, e_r)
        lhs = P[1] ** 2 + P[2] ** 2 + P[3] ** 2 / e_r**2
        assert lhs <= (mu * P[0]) ** 2 * (1 + 1e-12) + 1e-300


def test_projection_is_the_mathmd_formula_and_a_projection(rng):
    for _ in range(500):
        d = rng.integers(2, 5)
        x = rng.standard_normal(d) * 3
        mu = rng.uniform(0.0, 2.0)
        p = project_cone(x, mu)
        # idempotent, inside K, x − p ⊥ p and x − p ∈ −K* (normal cone at p)
        np.testing.assert_allclose(project_cone(p, mu), p, atol=1e-14)
        assert np.linalg.norm(p[1:]) <= mu * p[0] + 1e-14
        assert abs((x - p) @ p) <= 1e-12 * (1 + np.linalg.norm(x) ** 2)
        y = p - x
        assert mu * np.linalg.norm(y[1:]) <= y[0] + 1e-12
    np.testing.assert_array_equal(project_cone(np.array([-1.0, 0.1, 0.1]), 0.5), 0.0)


@pytest.mark.parametrize("d", [2, 3, 4])
def test_singular_blocks_never_give_nan(rng, d):
    for kind in range(3):
        for _ in range(200):
            if kind == 0:
                W = np.zeros((d, d))
            elif kind == 1:
                b = rng.standard_normal(d)
                W = np.outer(b, b)
            else:
                B = rng.standard_normal((d, d - 1))
                W = B @ B.T
            alpha = rng.standard_normal(d)
            mu = rng.choice([0.0, 0.3, 2.0])
            P, status, _ = solve_any(W, alpha, mu, 0.1)
            assert np.all(np.isfinite(P))
            if status != FAILED:  # whatever is claimed solved satisfies the law
                assert law_violation(W, alpha, mu, P, 0.1 if d == 4 else None) <= LAW_TOL
            else:  # the fallback is one of the safe candidates: open or normal-only
                assert np.all(P[1:] == 0.0) and P[0] >= 0.0


@pytest.mark.parametrize("cond", [None, 1e4])
def test_warm_started_slide_newton_agrees_with_the_general_solver(rng, cond):
    """The engine's sliding shortcut (Newton on the slip direction from a nearby impulse) gives
    the general solver's impulse when it answers, declines a sticking or open contact, and
    answers most sliding ones."""
    from fixplan.engine.local import slide3_newton

    answered = slides = 0
    for trial in range(600):
        W = random_spd(rng, 3, cond)
        if trial % 3 == 0:  # a nonsymmetric block with positive definite symmetric part
            W = W + 0.2 * (lambda S: S - S.T)(rng.standard_normal((3, 3))) * np.abs(W).max()
        alpha = rng.standard_normal(3) * 10.0 ** rng.uniform(-3, 3)
        mu = [0.3, 1.0, rng.uniform(0.05, 2.0)][trial % 3]
        P_ref, status, _ = solve_coulomb_3d(W, alpha, mu)
        slides += status == SLIDE
        # start: the reference impulse turned by up to ~0.3 rad (a previous sweep's), or a random one
        turn = rng.normal(scale=0.1)
        c, s = np.cos(turn), np.sin(turn)
        start = np.array([1.0, c * P_ref[1] - s * P_ref[2], s * P_ref[1] + c * P_ref[2]])
        if trial % 5 == 0 or not np.any(start[1:]):
            start = rng.standard_normal(3)
        P = start.copy()
        if slide3_newton(W, alpha, mu, P):
            answered += 1
            assert status == SLIDE, (W, alpha, mu, status)
            assert np.allclose(P, P_ref, rtol=1e-10, atol=1e-12 * np.abs(P_ref).max()), (P, P_ref)
            assert law_violation(W, alpha, mu, P) <= LAW_TOL
        else:
            assert np.array_equal(P, start)  # declined: P untouched
    assert slides > 100 and answered >= 0.7 * slides
