"""A tiny friction coefficient is as exact as none.

box-3-2-1 with μ = 1e-12 classified a 1 N push along +x as ``jammed`` with certificate
``static-balance``, E1's normal force −1 N and a cone violation of 7e-14: the cone was written on
``(μ f_n, f_t)``, so the normal force's sign was a constraint weighted by μ. At μ = 1e-10 the
margin was 0.24 against 1/√m = 0.707. The cones are now written on the scaled tangential force
(``f_t = μ s``, ``‖s‖ ≤ f_n``), and every program's forces are checked in the mechanics' terms
and moved into the cones before a verdict rests on them.

Physics: the push is 1 N along +x, away from E1 (the only locator that could resist it without
friction); with μ → 0 the least ``M⁻¹``-weighted residual is the push itself, ``1/√m``, and
friction can lower it by at most ``μ Σ λ_n / √m``. So the verdicts are continuous with μ = 0's,
the margins within ``μ`` times the forces of μ = 0's, and both backends agree.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from conftest import PROBLEMS
from conftest import box_on_three_supports as box_on_supports

import fixplan
from fixplan.jamming import classify
from fixplan.jamming.programs import force_cone_violation, into_cones
from fixplan.locating import contact_set

MUS = [0.0, 1e-14, 1e-12, 1e-10, 1e-9, 1e-6]
BOX = (PROBLEMS / "box-3-2-1.toml").read_text()


def _box_321(mu: float) -> fixplan.Fixture:
    return fixplan.loads(re.sub(r"friction = [0-9.e+-]+", f"friction = {mu!r}", BOX))


def _margin_bound(mu: float, mass: float, total_N: float) -> float:
    """How far friction μ can move the margin from μ = 0's: μ Σλ_n/√m, plus the solvers' accuracy."""
    return 2.0 * mu * total_N / math.sqrt(mass) + 1e-7


def _assert_in_cones(fixture: fixplan.Fixture, r, contacts=None, pose=None) -> None:  # type: ignore[no-untyped-def]
    cs = contact_set(fixture, pose or "start", contacts)
    lam = np.concatenate([r.contact_forces[c.name] for c in cs.contacts])
    scale = max(1.0, float(np.abs(lam).max()))
    assert force_cone_violation(cs, lam) <= 1e-9 * scale, (r.mode, r.certificate, lam)


@pytest.mark.parametrize("backend", ["clarabel", "cvxpy"])
@pytest.mark.parametrize("mu", MUS)
def test_box_321_push_away_from_e1_separates_at_every_tiny_mu(mu, backend):
    """The reported case: separates with margin 1/√m at every μ ≤ 1e-6, forces in the cones."""
    f = _box_321(mu)
    r = classify(f, [1.0, 0, 0, 0, 0, 0], backend=backend)[0]
    assert r.mode == "separates", (r.mode, r.certificate, r.reason)
    m = f.workpiece.mass_kg
    assert r.margin == pytest.approx(1.0 / math.sqrt(m), abs=_margin_bound(mu, m, 20.62))
    assert r.contact_forces["E1"][0] >= 0.0  # a negative normal force is never a balance
    _assert_in_cones(f, r)


def _random_wrenches(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack(
        [
            rng.uniform(-8, 8, n),
            rng.uniform(-8, 8, n),
            rng.uniform(-30, 5, n),
            rng.uniform(-0.3, 0.3, n),
            rng.uniform(-0.3, 0.3, n),
            rng.uniform(-0.3, 0.3, n),
        ]
    )


@pytest.mark.parametrize(
    ("name", "make", "pose"),
    [
        ("box-3-2-1", _box_321, "start"),
        ("three-supports", lambda mu: box_on_supports(mu=mu), "start"),
        ("three-supports-soft", lambda mu: box_on_supports(mu=mu, torsion=0.01), "start"),
    ],
)
def test_verdicts_and_margins_are_continuous_at_mu_zero(name, make, pose):
    """Seeded wrenches: every μ ≤ 1e-6 gives μ = 0's verdict and margin, on both backends."""
    rng = np.random.default_rng(2026)
    W = _random_wrenches(rng, 8)
    reference = {b: classify(make(0.0), W, backend=b, pose=pose) for b in ("clarabel", "cvxpy")}
    # the two backends agree at μ = 0 (the reference the others are held to)
    for a, b in zip(reference["clarabel"], reference["cvxpy"], strict=True):
        assert a.mode == b.mode
        assert a.margin == pytest.approx(b.margin, rel=1e-5, abs=1e-7)
    for mu in MUS[1:]:
        f = make(mu)
        m = f.workpiece.mass_kg
        for backend in ("clarabel", "cvxpy"):
            for w, r0, r in zip(W, reference[backend], classify(f, W, backend=backend, pose=pose), strict=True):
                weight = m * 9.81 + float(np.abs(w[:3]).sum())
                where = f"{name} μ={mu} {backend} w={w.round(3).tolist()}"
                assert r.mode == r0.mode, f"{where}: {r.mode} ({r.certificate}) vs {r0.mode} at μ = 0"
                assert r.margin == pytest.approx(r0.margin, abs=_margin_bound(mu, m, weight)), where
                _assert_in_cones(f, r, pose=pose)


def test_into_cones_moves_only_what_is_outside():
    """λ inside the cones is returned unchanged; outside, a negative normal goes to 0 and the tangential shrinks to μ λ_n."""
    f = _box_321(0.25)
    cs = contact_set(f, "start", None)
    rng = np.random.default_rng(7)
    for _ in range(200):
        lam = rng.normal(size=cs.J.shape[0])
        fixed = into_cones(cs, lam)
        assert force_cone_violation(cs, fixed) <= 1e-15
        for c, o in zip(cs.contacts, cs.offsets, strict=True):
            before, after = lam[o : o + c.size], fixed[o : o + c.size]
            assert after[0] == max(before[0], 0.0)
            t_before, t_after = np.linalg.norm(before[1:]), np.linalg.norm(after[1:])
            if t_before <= c.friction * after[0]:
                assert np.array_equal(before[1:], after[1:])
            else:  # shrunk onto the cone's surface, same direction
                assert t_after == pytest.approx(c.friction * after[0], rel=1e-12, abs=1e-300)
                assert np.allclose(after[1:] * t_before, before[1:] * t_after)
