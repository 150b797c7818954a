"""Jamming analysis against closed forms derived by hand (see each test's docstring)."""

import numpy as np
import pytest
from conftest import box_on_three_supports as box_on_supports

import fixplan
from fixplan.jamming import can_wedge, classify, search_wrench, wedge_force


def peg(depth, r=0.01, mu=0.3, gravity="[0.0, 0.0]"):
    """2D peg in a hole, two-point contact: A on the left wall at height depth (normal +x), B on the right at 0 (normal -x).

    The body origin is the peg tip centre (0, 0)."""
    return fixplan.loads(
        f"""format = 1
[scene]
name = "peg"
dimension = 2
gravity = {gravity}
[workpiece]
shape = "rectangle"
size = [{2 * r}, {4 * depth + 0.1}]
mass = 0.5
start = {{ position = [0.0, 0.0] }}
[[contact]]
name = "A"
point = [{-r}, {depth}]
normal = [1.0, 0.0]
friction = {mu}
[[contact]]
name = "B"
point = [{r}, 0.0]
normal = [-1.0, 0.0]
friction = {mu}
"""
    )


def test_box_on_three_supports_held_jammed_slides_closed_form():
    """Held by gravity alone; a push through the CoM jams iff F ≤ μ m g, else slides with a = (F − μ m g)/m."""
    f = box_on_supports(mu=0.3, mass=2.0)
    limit = 0.3 * 2.0 * 9.81
    assert classify(f, [0, 0, 0, 0, 0, 0])[0].mode == "held"
    for F in (0.5 * limit, 0.95 * limit):
        r = classify(f, [F, 0, 0, 0, 0, 0])[0]
        assert r.mode == "jammed" and r.margin <= 1e-6 * F
        total = sum(r.force_world(n) for n in r.contact_forces)
        assert np.allclose(total, [-F, 0, 2.0 * 9.81], atol=1e-5)
    for F in (1.05 * limit, 3 * limit):
        r = classify(f, [F, 0, 0, 0, 0, 0])[0]
        assert r.mode == "slides"
        assert r.acceleration[0] == pytest.approx((F - limit) / 2.0, rel=1e-8)
        assert np.allclose(r.acceleration[1:], 0, atol=1e-9)
        for name, lam in r.contact_forces.items():  # friction at the cone's edge, opposing the slip
            assert np.hypot(lam[1], lam[2]) == pytest.approx(0.3 * lam[0], rel=1e-8)
            assert r.force_world(name)[0] < 0


def test_lift_separates_and_pull_along_normal():
    f = box_on_supports()
    assert classify(f, [0, 0, 2.0 * 9.81 * 1.1, 0, 0, 0])[0].mode == "separates"
    assert classify(f, [0, 0, 2.0 * 9.81 * 0.9, 0, 0, 0])[0].mode == "held"


@pytest.mark.parametrize("mu", [0.0, 2.0])
def test_extreme_friction(mu):
    """μ = 0: any horizontal push slides; μ = 2: a push below 2 m g jams, above it slides.

    The push acts in the support plane (``at`` z = 0) so friction cannot tip the box: with μ = 2
    a push at the centre of mass would need 0.98 N·m from the supports, which can give only 0.59."""
    f = box_on_supports(mu=mu)
    r = classify(f, [1.0, 0, 0, 0, 0, 0], at=[0.0, 0.0, 0.0])[0]
    if mu == 0.0:
        assert r.mode == "slides" and r.acceleration[0] == pytest.approx(0.5, rel=1e-9)
    else:
        assert r.mode == "jammed"
        r = classify(f, [1.1 * 2 * 2 * 9.81, 0, 0, 0, 0, 0], at=[0.0, 0.0, 0.0])[0]
        assert r.mode == "slides" and r.acceleration[0] == pytest.approx(0.1 * 2 * 9.81 * 2 / 2, rel=1e-8)


@pytest.mark.parametrize(
    "wrench",
    [
        [1.0, 0.3, -2.0, 0, 0, 0.01],
        [0.2, -0.1, -1.0, 0.0, 0.0, 0.0],
        [3.0, 1.0, -1.0, 0, 0, 0.05],
        [0, 0, 1.0, 0, 0, 0],
    ],
)
def test_mode_invariant_under_scaling_in_zero_gravity(wrench):
    """Without gravity the problem is homogeneous: 1e-6 N and 1e6 N give the same verdict."""
    f = box_on_supports(gravity=(0.0, 0.0, 0.0))
    modes = {classify(f, [np.array(wrench) * s])[0].mode for s in (1e-6, 1e-3, 1.0, 1e3, 1e6)}
    assert len(modes) == 1, modes


def test_boundary_wrenches_never_raise():
    """Within 1e-9 of the slide threshold the verdict is definite or indeterminate, never an exception."""
    f = box_on_supports(mu=0.3)
    limit = 0.3 * 2.0 * 9.81
    for F in (limit - 1e-9, limit, limit + 1e-9):
        r = classify(f, [F, 0, 0, 0, 0, 0])[0]
        assert r.mode in ("jammed", "slides", "indeterminate")
        assert np.isfinite(r.margin)


def test_backends_agree():
    """The Clarabel matrix path and the independent cvxpy model give the same modes and margins."""
    f = box_on_supports(mu=0.25)
    rng = np.random.default_rng(0)
    W = np.column_stack(
        [
            rng.uniform(-8, 8, 12),
            rng.uniform(-8, 8, 12),
            rng.uniform(-30, 5, 12),
            np.zeros(12),
            np.zeros(12),
            rng.uniform(-0.3, 0.3, 12),
        ]
    )
    fast = classify(f, W)
    ref = classify(f, W, backend="cvxpy")
    for a, b in zip(fast, ref, strict=True):
        assert a.mode == b.mode
        assert a.margin == pytest.approx(b.margin, rel=1e-5, abs=1e-7)


def test_six_locators_located_box():
    """At the goal of the 3-2-1 box: pushing into the locators is held, pulling away separates."""
    f = fixplan.load(fixplan.default_fixture_path())
    assert classify(f, [-5, -5, -5, 0, 0, 0], pose="goal")[0].mode == "held"
    # base friction plus side-locator friction resist up to μ m g √(1+μ²) = 5.06 N: 8 N must open E1
    assert classify(f, [5, 0, 0, 0, 0, 0], pose="goal")[0].mode == "jammed"
    assert classify(f, [8, 0, 0, 0, 0, 0], pose="goal")[0].mode == "separates"
    r = classify(f, [-5, -5, -5, 0, 0, 0], pose="goal")[0]
    total = sum(r.force_world(n) for n in r.contact_forces)
    assert np.allclose(total, [5, 5, 5 + 2 * 9.81], atol=1e-6)


def test_concurrent_normals_rank_deficient():
    """Three frictionless contacts on a disk: normals meet at the centre (rank G = 2 < 3).

    Any moment turns the disk freely (it slides at every contact); forces through the centre are held."""
    f = fixplan.loads(
        """format = 1
[scene]
name = "disk"
dimension = 2
gravity = [0.0, 0.0]
[workpiece]
shape = "disk"
radius = 0.05
mass = 1.0
start = { position = [0.0, 0.0] }
[[locator]]
name = "L1"
position = [0.0, -0.05]
friction = 0.0
[[locator]]
name = "L2"
position = [0.0433012701892, 0.025]
friction = 0.0
[[locator]]
name = "L3"
position = [-0.0433012701892, 0.025]
friction = 0.0
"""
    )
    cs = fixplan.contact_set(f)
    assert np.linalg.matrix_rank(cs.G) == 2
    assert classify(f, [0.0, 0.0, 0.01])[0].mode == "slides"
    assert classify(f, [1.0, 2.0, 0.0])[0].mode == "held"


def test_wedging_iff_depth_below_2_r_mu():
    """Two-point contact with horizontal normals wedges iff depth < 2 r μ (Whitney)."""
    r, mu = 0.01, 0.3
    for depth in (0.5 * 2 * r * mu, 0.9 * 2 * r * mu):
        assert can_wedge(fixplan.contact_set(peg(depth, r, mu)))
    for depth in (1.1 * 2 * r * mu, 3 * 2 * r * mu):
        assert not can_wedge(fixplan.contact_set(peg(depth, r, mu)))
    assert wedge_force(fixplan.contact_set(peg(3 * 2 * r * mu, r, mu))) == pytest.approx(0.0, abs=1e-7)


def _peg_expected(Fx, Fy, Mz, depth, r, mu):
    """Closed form for the two-point peg (moments about the tip centre, insertion pushes Fy < 0).

    Sliding down (friction +y at both contacts): N_A = (Mz + μ r Fx)/depth, N_B = Fx + N_A, and the
    peg accelerates down iff −Fy > μ (N_A + N_B). Static balance: with T_A free,
    N_A = (Mz − r Fy − 2 r T_A)/depth, N_B = Fx + N_A, T_B = −Fy − T_A, |T| ≤ μ N, N ≥ 0.
    """
    NA = (Mz + mu * r * Fx) / depth
    NB = Fx + NA
    if NA > 0 and NB > 0 and -Fy > mu * (NA + NB):
        return "slides"
    for TA in np.linspace(-abs(Fy) * 5 - 10, abs(Fy) * 5 + 10, 200001):
        nA = (Mz - r * Fy - 2 * r * TA) / depth
        nB = Fx + nA
        TB = -Fy - TA
        if nA >= 0 and nB >= 0 and abs(TA) <= mu * nA and abs(TB) <= mu * nB:
            return "balanced"
    return "other"


def test_peg_whitney_two_point_contact():
    """Inside the sliding region (Whitney's parallelogram side for two-point contact) the peg slides; outside it jams or a contact opens."""
    depth, r, mu = 0.03, 0.01, 0.3
    f = peg(depth, r, mu)
    grid = [(Fx, -10.0, Mz) for Fx in (-4.0, -1.0, 0.5, 2.0, 5.0) for Mz in (-0.2, -0.05, 0.02, 0.1, 0.3)]
    results = classify(f, grid)
    for (Fx, Fy, Mz), res in zip(grid, results, strict=True):
        expected = _peg_expected(Fx, Fy, Mz, depth, r, mu)
        if expected == "slides":
            assert res.mode == "slides", (Fx, Mz, res.mode)
        elif expected == "balanced":
            assert res.mode in ("jammed", "held"), (Fx, Mz, res.mode)
        else:
            assert res.mode in ("separates", "pivots", "rolls"), (Fx, Mz, res.mode)


def test_search_finds_nonjamming_push_and_respects_limits():
    f = fixplan.load(fixplan.default_fixture_path())
    res = search_wrench(f, [0.1, 0, 0, 0, 0, 0])
    assert res.found and res.check.mode == "slides"
    assert np.linalg.norm(res.wrench[:3]) <= 40.0 + 1e-6
    assert np.linalg.norm(res.wrench[3:]) <= 2.0 + 1e-6
    assert res.check.acceleration[0] >= 0.1 - 1e-6


def test_search_reports_weak_manipulator():
    text = fixplan.default_fixture_path().read_text().replace("max_force = 40.0", "max_force = 1.0")
    f = fixplan.loads(text)
    res = search_wrench(f, [0.1, 0, 0, 0, 0, 0])
    assert not res.found and "too weak" in res.reason


@pytest.mark.parametrize("roles", [((), ()), ((1,), ()), ((), (2,)), ((0,), (2,))])
@pytest.mark.parametrize("soft", [False, True])
def test_witness_jacobian_matches_finite_differences(roles, soft, rng):
    """The analytic Jacobian of the kept/sliding/sticking/open system, against central differences."""
    from fixplan.jamming.sliding import Rows, _start_for
    from fixplan.settings import DEFAULT

    f = box_on_supports(mu=0.4, torsion=0.01 if soft else 0.0)
    cs = fixplan.contact_set(f)
    rows = Rows(cs)
    w = rng.normal(size=6)
    base = np.concatenate([rng.normal(size=6), rng.uniform(0.5, 2.0, size=3)])
    z = _start_for(cs, base, roles, DEFAULT.witness.seed_force)
    z[6:] += rng.normal(size=z.shape[0] - 6) * 0.1
    F, Jac, _ = rows.system(w, z, roles)
    eps = 1e-6
    fd = np.empty_like(Jac)
    for k in range(z.shape[0]):
        dz = np.zeros_like(z)
        dz[k] = eps
        fd[:, k] = (rows.system(w, z + dz, roles)[0] - rows.system(w, z - dz, roles)[0]) / (2 * eps)
    assert np.allclose(Jac, fd, atol=1e-7 * max(1.0, np.abs(Jac).max()))


def test_the_direct_csc_build_is_scipys_matrix_to_the_bit() -> None:
    """``csc_from_dense`` hands Clarabel exactly the arrays ``scipy.sparse.csc_matrix`` would."""
    import scipy.sparse as sp

    from fixplan.jamming.backends import csc_from_dense

    rng = np.random.default_rng(0)
    for trial in range(300):
        A = rng.normal(size=(int(rng.integers(1, 20)), int(rng.integers(1, 12))))
        A[rng.random(A.shape) < 0.4] = 0.0
        if trial % 25 == 0:
            A[:] = 0.0
        ours, theirs = csc_from_dense(A), sp.csc_matrix(A)
        assert ours.shape == theirs.shape
        for name in ("indptr", "indices", "data"):
            a, b = getattr(ours, name), getattr(theirs, name)
            assert a.dtype == b.dtype and np.array_equal(a, b)


def test_polygon_edges_are_computed_once_and_cannot_be_changed() -> None:
    """The cached edge arrays equal a fresh computation and are read-only (shared by every call)."""
    from fixplan.geometry.shapes import Polygon

    poly = Polygon(((0.0, 0.0), (0.2, 0.0), (0.25, 0.1), (0.0, 0.12)))
    V, E, N = poly._edges()
    assert poly._edges()[0] is V
    assert np.array_equal(E, np.roll(poly.array, -1, axis=0) - poly.array)
    assert np.allclose(np.linalg.norm(N, axis=1), 1.0) and np.allclose(np.einsum("ij,ij->i", E, N), 0.0)
    with pytest.raises(ValueError):
        N[0, 0] = 1.0


def test_one_wrench_one_verdict_whatever_the_batch():
    """A wrench's verdict does not depend on the batch it is classified in, nor on its place there.

    The witness search draws random starts; one generator shared by a whole batch gave the i-th
    wrench starts that depended on the wrenches before it (the demo map's (Fx −4.8718, Tz 0.02564)
    was indeterminate in the 40 × 40 map and slides alone). 2000 wrenches around the demo map's
    plane and off it, classified in order, in chunks on two processes, reversed, shuffled, and 200
    of them one at a time.
    """
    import numpy as np

    import fixplan
    from fixplan.jamming import classify

    fx = fixplan.load(fixplan.default_fixture_path())
    rng = np.random.default_rng(7)
    # the demo map's 40 × 40 grid (`fixplan map --axes Fx,Tz --range -10:10,-1:1 --n 40`), in its order
    grid = np.array([[fx_, 0, 0, 0, 0, tz] for tz in np.linspace(-1, 1, 40) for fx_ in np.linspace(-10, 10, 40)])
    extra = rng.normal(size=(400, 6)) * [8, 8, 8, 0.5, 0.5, 0.5]
    W = np.vstack([grid, extra])
    assert W.shape[0] == 2000

    def modes(batch, jobs=1):
        return [c.mode for c in classify(fx, batch, jobs=jobs)]

    forward = modes(W)
    assert modes(W, jobs=2) == forward  # in chunks on two worker processes
    assert modes(grid, jobs=2) == forward[:1600]  # the map's batch, in the map's chunks
    backward = modes(W[::-1])[::-1]
    perm = rng.permutation(W.shape[0])
    shuffled = np.empty(W.shape[0], dtype=object)
    shuffled[perm] = modes(W[perm])
    assert forward == backward
    assert forward == list(shuffled)
    idx = np.random.default_rng(7).permutation(W.shape[0])[:200]
    assert [classify(fx, W[i], jobs=1)[0].mode for i in idx] == [forward[i] for i in idx]
    # the demo map's point
    i = 20 * 40 + 10
    assert np.allclose(W[i], [-4.871794871794872, 0, 0, 0, 0, 0.02564102564102564])
    assert forward[i] == classify(fx, W[i], jobs=1)[0].mode == "slides"


WEDGE_BLOCK = """
format = 1
[scene]
name = "block-5kg"
dimension = 3
gravity = [0.0, 0.0, -9.81]
[workpiece]
shape = "box"
size = [0.20, 0.10, 0.05]
mass = 5.0
start = { position = [0.10, 0.05, 0.025], rpy_deg = [0.0, 0.0, 0.0] }
[[locator]]
name = "B1"
position = [0.035, 0.015, -0.005]
radius = 0.005
friction = 0.2
[[locator]]
name = "B2"
position = [0.165, 0.015, -0.005]
radius = 0.005
friction = 0.2
[[locator]]
name = "B3"
position = [0.10, 0.085, -0.005]
radius = 0.005
friction = 0.2
[[locator]]
name = "S1"
position = [0.04, -0.005, 0.025]
radius = 0.005
friction = 0.2
[[locator]]
name = "S2"
position = [0.16, -0.005, 0.025]
radius = 0.005
friction = 0.2
[[locator]]
name = "E1"
position = [-0.005, 0.05, 0.025]
radius = 0.005
friction = 0.2
"""


@pytest.mark.parametrize("push_N", [9.9, 10.0])
def test_a_jam_that_rests_on_wedging_forces_says_so(push_N):
    # a 5 kg block at its goal on three base locators (μ = 0.2: μ m g = 9.81 N) pushed along +x:
    # above 9.81 N the base alone cannot hold it, but a "balance" exists with the side locators
    # pressed (+y) against base friction (−y) and their friction resisting the push — forces that
    # nothing presses (the push is along x, gravity along z)
    import fixplan
    from fixplan.jamming import classify

    fx = fixplan.loads(WEDGE_BLOCK)
    w = [push_N, 0, 0, 0, 0, 0]
    c = classify(fx, w, jobs=1)[0]
    assert c.mode == "jammed" and c.certificate == "wedging", (c.mode, c.certificate, c.reason)
    assert "S1, S2" in c.reason and "unloaded the push slides" in c.reason
    # the other reading: the loaded contacts alone
    alone = classify(fx, w, ["B1", "B2", "B3"], jobs=1)[0]
    assert alone.mode == "slides"
    # the balance indeed loads the side locators, and only through internal forces: their normal
    # forces sum to a y-force that base friction cancels
    side = sum(c.contact_forces[n][0] for n in ("S1", "S2"))
    assert side > 1e-3


def test_a_push_below_the_friction_limit_is_held_by_the_base_not_by_wedging():
    import fixplan
    from fixplan.jamming import classify

    fx = fixplan.loads(WEDGE_BLOCK)
    c = classify(fx, [9.0, 0, 0, 0, 0, 0], jobs=1)[0]  # 9 N < μ m g = 9.81 N: the base's friction holds it
    assert c.mode == "jammed" and c.certificate == "static-balance"
    into = classify(fx, [-10.0, -10.0, 0, 0, 0, 0], jobs=1)[0]  # into the corner: the locators carry it
    assert into.mode == "held"
