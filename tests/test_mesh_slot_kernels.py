"""The compiled mesh step (:mod:`fixplan.engine._mesh_slot_kernels`) answers what the Python path answers.

The engine steps a mesh part in one compiled call (detection, plane slots, the collision points
near their obstacles, warm starts, the step, its write-back). The Python path it replaced is kept
as the reference: :func:`fixplan.engine.mesh_slots.mesh_slots` for the slots and
``Simulator._step_mesh_reference`` for the step (``sim._mesh_reference = True``). On a box written
as a mesh and on an L-bracket with a tip in its concave corner (two contacts of one locator), the
two give the same slots (locator, rank, gap, contact point, plane frame) at seeded poses, the same
collision points near a floor and a plate, and step for step (each from the same state) the same
poses, twists, impulses, gaps, normals and per-contact reports, to 1e-12 (impulses in N·s, so forces to 1e-12 N·s / dt).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS

from fixplan.engine import _mesh_slot_kernels as kernels
from fixplan.engine.mesh_slots import MeshStepper, mesh_slots
from fixplan.engine.simulator import Simulator
from fixplan.fixture import load
from fixplan.geometry import Mesh
from fixplan.geometry.cells import box_cells, cell_surface, l_bracket_cells
from fixplan.geometry.mesh import stl_bytes
from fixplan.model import Locator
from fixplan.spatial import exp_so3

TOL = 1e-12
CORNER_M = np.array([0.013, 0.02, 0.013])  # a tip of radius 3 mm in the L's concave corner (x = z = 0.01)


def _locators(points: np.ndarray, radius_m: float = 0.003) -> tuple[Locator, ...]:
    return tuple(Locator(f"L{i}", np.asarray(p, dtype=float), radius_m, 0.4) for i, p in enumerate(points))


def _empty_cache(mesh: Mesh, k: int) -> tuple[np.ndarray, np.ndarray]:
    """No triangles remembered (every query a full one until it fills them)."""
    cache_q = np.zeros((k, 5))
    cache_q[:, 3] = -1.0
    return cache_q, np.zeros((k, mesh.settings.query_cache_triangles), dtype=np.int64)


def _compiled_slots(
    mesh: Mesh,
    locators: tuple[Locator, ...],
    R: np.ndarray,
    p: np.ndarray,
    band: float,
    cache: tuple[np.ndarray, np.ndarray] | None = None,
):
    loc = np.array([[*x.p_world, x.radius_m, x.friction, x.torsion_m] for x in locators])
    cache_q, cache_ids = _empty_cache(mesh, len(locators)) if cache is None else cache
    radius = mesh.settings.query_cache_radius_m
    return kernels.locator_slots(R, p, *mesh.query_arrays, mesh.same_point_m, loc, band, radius, cache_q, cache_ids)


def assert_same_slots(
    mesh: Mesh,
    locators: tuple[Locator, ...],
    R: np.ndarray,
    p: np.ndarray,
    band: float,
    cache: tuple[np.ndarray, np.ndarray] | None = None,
) -> int:
    """The compiled slots equal :func:`mesh_slots`'s (locator, rank, gap, point, plane row); their count."""
    want = mesh_slots(mesh, locators, R, p, band)
    n, owner, rank, x_body, obs, gap = _compiled_slots(mesh, locators, R, p, band, cache)
    assert n == len(want)
    assert np.array_equal(owner[:n], want.locator) and np.array_equal(rank[:n], want.rank)
    np.testing.assert_allclose(gap[:n], want.gap_m, rtol=0, atol=TOL)
    np.testing.assert_allclose(x_body[:n], want.slots[:, :3], rtol=0, atol=TOL)
    np.testing.assert_allclose(obs[:n], want.obs, rtol=0, atol=TOL)  # kind, o_world, R_world_plane
    return n


def _poses(rng: np.random.Generator, count: int, angle_rad: float, shift_m: float):
    for _ in range(count):
        yield exp_so3(rng.uniform(-angle_rad, angle_rad, size=3)), rng.uniform(-shift_m, shift_m, size=3)


def test_slots_on_a_box_mesh_match_the_python_path(rng: np.random.Generator) -> None:
    """Tips under, beside and over a split box (on faces, edges and corners), at seeded poses and bands."""
    mesh = Mesh(*cell_surface(*box_cells((0.2, 0.1, 0.05), 4)))
    tips = np.array(
        [[-0.06, -0.03, -0.028], [0.07, 0.0, -0.028], [0.103, 0.0, 0.0], [0.0, 0.053, 0.01], [0.102, 0.052, 0.027]]
    )
    counts = []
    for R, p in _poses(rng, 40, 0.05, 0.002):
        for band in (0.0, 1e-4, 2e-3):
            counts.append(assert_same_slots(mesh, _locators(tips), R, p, band))
    assert min(counts) == len(tips)  # every locator has its nearest contact, however far


def test_remembered_triangles_give_the_full_querys_slots_to_the_bit(rng: np.random.Generator) -> None:
    """A tip that moves in small steps, with the bands the engine uses (its margin grows with speed):
    each step's slots from the remembered triangles equal the Python path's (1e-12) and a fresh full
    query's to the bit, on faces, edges and corners of a split box and in the L's concave corner;
    most steps reuse the remembered triangles, and a move beyond the radius queries the tree again."""
    radius = Mesh(*cell_surface(*box_cells((0.2, 0.1, 0.05), 4))).settings.query_cache_radius_m
    cases = (
        (
            Mesh(*cell_surface(*box_cells((0.2, 0.1, 0.05), 40))),
            np.array([[-0.06, -0.03, -0.028], [0.103, 0.0, 0.0], [0.102, 0.052, 0.027], [0.0, 0.0501, 0.0249]]),
        ),
        (Mesh(*cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01))), np.array([CORNER_M, [0.05, 0.02, -0.003]])),
    )
    for mesh, tips in cases:
        locators = _locators(tips)
        cache = _empty_cache(mesh, len(locators))
        R, p = np.eye(3), np.zeros(3)
        reused = refilled = 0
        for step in range(300):
            # small steps, now and then a jump of several radii; bands from the margin to its fast-motion size
            jump = step % 50 == 49
            p = p + rng.normal(scale=(40.0 if jump else 0.15) * radius, size=3)
            R = exp_so3(rng.normal(scale=2e-4, size=3)) @ R
            band = float(rng.choice([1e-4, 1.2e-4, 2e-4]))
            before = cache[0].copy()
            got = _compiled_slots(mesh, locators, R, p, band, cache)
            n = assert_same_slots(mesh, locators, R, p, band)  # a full query: the Python path's slots
            fresh = _compiled_slots(mesh, locators, R, p, band)
            assert got[0] == fresh[0] == n
            for a, b in zip(got[1:], fresh[1:], strict=True):
                assert np.array_equal(a[:n], b[:n])  # bit for bit
            same_point = np.all(cache[0][:, :3] == before[:, :3], axis=1)
            reused += int(np.sum(same_point & (before[:, 3] >= 0)))
            refilled += int(np.sum(~same_point))
        assert reused > 5 * refilled > 0, (reused, refilled)  # the memory is used, and renewed when the tip leaves it


def test_slots_in_the_l_corner_match_the_python_path_with_two_contacts(rng: np.random.Generator) -> None:
    """A tip in the L's concave corner: two slots of one locator, the wall's and the base's, with their normals."""
    mesh = Mesh(*cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01)))
    locators = _locators(np.array([CORNER_M, [0.05, 0.02, -0.003], [0.013, 0.02, 0.04]]))
    n, owner, rank, x_body, obs, gap = _compiled_slots(mesh, locators, np.eye(3), np.zeros(3), 1e-4)
    assert n == 4 and owner[:n].tolist() == [0, 0, 1, 2] and rank[:n].tolist() == [0, 1, 0, 0]
    np.testing.assert_allclose(gap[:2], 0.0, rtol=0, atol=TOL)
    normals = sorted(tuple(np.round(row[[6, 9, 12]], 12)) for row in obs[:2])  # R_world_plane's last column
    assert normals == [(-1.0, 0.0, 0.0), (0.0, 0.0, -1.0)]  # from the tip into the wall and into the base
    points = sorted(tuple(np.round(x, 12)) for x in x_body[:2])
    assert points == [(0.01, 0.02, 0.013), (0.013, 0.02, 0.01)]
    several = 0
    for R, p in _poses(rng, 60, 0.02, 0.0005):
        got = assert_same_slots(mesh, locators, R, p, 1e-4)
        several += got > len(locators)
    assert several > 0  # some poses keep both faces of the corner within the band


def test_the_collision_points_near_an_obstacle_are_those_the_python_path_hands_over(rng: np.random.Generator) -> None:
    """A split box over a floor plane and a plate (a box obstacle): the tree finds exactly the points the lower bound keeps."""
    mesh_box = Mesh(*cell_surface(*box_cells((0.2, 0.1, 0.05), 6)))
    obs = np.zeros((2, 16))
    obs[0, :4] = [0.0, 0.0, 0.0, -0.0253]  # a floor plane at z = -0.0253, normal +z
    obs[0, 4:13] = np.eye(3).reshape(-1)
    R_plate = exp_so3(np.array([0.0, 0.02, 0.0]))
    obs[1, :4] = [1.0, 0.0, 0.0, 0.0361]  # a plate over the box, 2 mm thick
    obs[1, 4:13] = R_plate.reshape(-1)
    obs[1, 13:16] = [0.15, 0.1, 0.01]
    V = mesh_box.vertices
    slots = np.concatenate([np.column_stack([V, np.zeros(len(V)), np.full(len(V), float(j))]) for j in range(2)])
    mu = np.full(len(slots), 0.3)
    stepper = MeshStepper(mesh_box, _locators(np.zeros((1, 3))), obs, slots, mu)
    found = np.empty(len(slots), dtype=np.int64)
    hits = 0
    for R, p in _poses(rng, 200, 0.03, 0.002):
        margin = float(rng.choice([1e-4, 1e-3, 5e-3]))
        n = kernels.points_near(R, p, obs, stepper.points, *stepper.tree, margin, mesh_box.same_point_m, found)
        local = [slots[:, :3] @ (obs[j, 4:13].reshape(3, 3).T @ R).T + obs[j, 4:13].reshape(3, 3).T @ (p - obs[j, 1:4])
                 for j in range(2)]  # fmt: skip
        lower = np.where(
            slots[:, 4] == 0,
            local[0][:, 2],
            np.linalg.norm(local[1], axis=1) - np.linalg.norm(obs[1, 13:16]),
        )
        want = np.flatnonzero(lower <= margin)
        assert np.array_equal(found[:n], want)
        hits += n
    assert hits > 0


def _corner_fixture(folder: Path) -> Path:
    """``l-bracket.toml`` with E1 in the concave corner and the part pressed into it by the test's wrench."""
    text = (PROBLEMS / "meshes" / "l-bracket.toml").read_text(encoding="utf-8")
    text = text.replace("position = [0.013, 0.02, 0.035]", "position = [0.013, 0.02, 0.013]")
    (folder / "l-bracket.stl").write_bytes((PROBLEMS / "meshes" / "l-bracket.stl").read_bytes())
    path = folder / "corner.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _box_on_floor(folder: Path, torsion_m: float = 0.0) -> Path:
    """A split box (4 × 4 squares a face) on a floor, three tips beside it (soft fingers when ``torsion_m > 0``)."""
    V, F = cell_surface(*box_cells((200.0, 100.0, 50.0), 4))
    (folder / "box.stl").write_bytes(stl_bytes(V, F))
    tips = [("S1", (-0.05, -0.0531, 0.0)), ("S2", (0.05, -0.0531, 0.0)), ("E1", (-0.1031, 0.0, 0.0))]
    text = (
        'format = 1\n[scene]\nname = "split box on a floor"\ndimension = 3\n'
        '[workpiece]\nshape = "mesh"\nfile = "box.stl"\nunits = "mm"\nmass = 2.0\n'
        "start = { position = [0.0, 0.0, 0.0] }\n"
        + "".join(
            f'[[locator]]\nname = "{name}"\nposition = [{x}, {y}, {z}]\nradius = 0.003\nfriction = 0.3\n'
            + (f"torsion = {torsion_m}\n" if torsion_m > 0.0 else "")
            for name, (x, y, z) in tips
        )
        + '[[obstacle]]\nname = "floor"\nshape = "plane"\npoint = [0.0, 0.0, -0.025]\nnormal = [0.0, 0.0, 1.0]\n'
    )
    (folder / "floor.toml").write_text(text)
    return folder / "floor.toml"


def assert_same_state(a: Simulator, b: Simulator) -> None:
    kl = a._k_loc
    for x, y in ((a._R, b._R), (a._p, b._p), (a._v, b._v), (a._w, b._w), (a._P, b._P), (a._u, b._u)):
        np.testing.assert_allclose(x, y, rtol=0, atol=TOL)
    assert np.array_equal(a._active, b._active)
    np.testing.assert_allclose(a._gap[:kl], b._gap[:kl], rtol=0, atol=TOL)
    np.testing.assert_allclose(a._nw[:kl], b._nw[:kl], rtol=0, atol=TOL)
    near = np.isfinite(b._gap)
    assert np.array_equal(np.isfinite(a._gap), near)  # the same collision points handed over
    np.testing.assert_allclose(a._gap[near], b._gap[near], rtol=0, atol=TOL)


def assert_same_reports(a: Simulator, b: Simulator) -> int:
    """The same per-locator and per-contact reports; the number of contacts reported one by one.

    Forces are impulses over the step: compared as impulses, to 1e-12 N·s (``TOL / dt`` in N).
    """
    tol_N = TOL / a.dt
    several = 0
    for x, y in zip(a.contacts(), b.contacts(), strict=True):
        assert (x.name, x.mode) == (y.name, y.mode)
        assert abs(x.gap_m - y.gap_m) <= TOL and abs(x.normal_force_N - y.normal_force_N) <= tol_N
        np.testing.assert_allclose(x.force_world, y.force_world, rtol=0, atol=tol_N)
        assert len(x.contacts) == len(y.contacts)
        several += len(x.contacts)
        for s, t in zip(x.contacts, y.contacts, strict=True):
            assert abs(s.gap_m - t.gap_m) <= TOL and abs(s.normal_force_N - t.normal_force_N) <= tol_N
            np.testing.assert_allclose(s.normal_world, t.normal_world, rtol=0, atol=TOL)
            np.testing.assert_allclose(s.force_world, t.force_world, rtol=0, atol=tol_N)
    for x, y in zip(a.obstacles(), b.obstacles(), strict=True):
        np.testing.assert_allclose(x.force_world, y.force_world, rtol=0, atol=tol_N)
    return several


def sync(a: Simulator, b: Simulator) -> None:
    """``a`` (compiled) takes ``b``'s (the Python path's) state and warm starts, in place.

    NSGS stops at a tolerance: rounding-level differences of its input (numpy's products against
    the kernel's scalar sums) may change a sweep count many steps later and then move impulses by
    more than 1e-12. So each step is compared from the same state.
    """
    for name in ("_R", "_p", "_v", "_w", "_P", "_P_prev", "_u", "_gap", "_nw", "_active", "_active_prev"):
        getattr(a, name)[...] = getattr(b, name)
    stepper, last = a._mesh_stepper, b._mesh_last
    assert stepper is not None and last is not None
    stepper.loc_slots[:] = 0
    for j, (i, rank) in enumerate(last.keys):
        old = b._mesh_state[(i, rank)]
        stepper.state[j, :12], stepper.state[j, 16:18] = old[:12], old[12:14]
        if rank == 0:
            stepper.loc_slots[i, 0] = j
        stepper.loc_slots[i, 1] += 1


@pytest.mark.parametrize("case", ["corner", "floor", "floor with soft fingers"])
def test_the_compiled_step_follows_the_python_step(tmp_path: Path, case: str) -> None:
    """Step for step from the same state (:func:`sync`): the L pressed into E1's corner (two loaded contacts), a split box slid along a floor."""
    if case == "corner":
        fixture = load(_corner_fixture(tmp_path))
        F = np.array([-1.0, 0.3, -2.0])  # into the corner, the base and the wall, and along y
        wrench = np.concatenate([F, np.cross(fixture.start.p_world + np.array([0.05, 0.02, 0.01]), F)])
        steps = 150
    else:
        fixture = load(_box_on_floor(tmp_path, 0.01 if "soft" in case else 0.0))
        wrench = np.array([8.0, -1.0, 0.0, 0.0, 0.0, 0.05])  # slides along S1 and S2 on the floor
        steps = 200
    compiled, reference = Simulator(fixture), Simulator(fixture)
    reference._mesh_reference = True
    several = 0
    for s in range(steps):
        ia, ib = compiled.step(wrench), reference.step(wrench)
        assert abs(ia.error - ib.error) <= TOL and ia.converged == ib.converged
        assert ia.penetration_m == pytest.approx(ib.penetration_m, abs=TOL)
        assert_same_state(compiled, reference)
        if s % 25 == 0 or s == steps - 1:
            several += assert_same_reports(compiled, reference)
        sync(compiled, reference)
    if case == "corner":
        assert several > 0  # E1 reported on the wall and the base
        (e1,) = [r for r in compiled.contacts() if r.name == "E1"]
        assert len(e1.contacts) == 2 and all(t.normal_force_N > 0.0 for t in e1.contacts)
    else:
        assert compiled.obstacles()[0].force_world[2] > 0.0  # the floor carries the box
        assert np.linalg.norm(compiled.twist[:3]) > 1e-3  # and it slides
    # a new state: no warm start, as in the Python path
    for sim in (compiled, reference):
        sim.set_state(fixture.start)
        sim.step(wrench)
    assert_same_state(compiled, reference)


def test_more_slots_than_the_state_holds_grows_it(tmp_path: Path) -> None:
    """The slots' state starts small here: the kernel says how many rows it needs, the stepper grows it."""
    fixture = load(_corner_fixture(tmp_path))
    compiled, reference = Simulator(fixture), Simulator(fixture)
    reference._mesh_reference = True
    stepper = compiled._mesh_stepper
    assert stepper is not None
    stepper.state = np.zeros((1, stepper.state.shape[1]))
    for _ in range(3):
        compiled.step(np.zeros(6))
        reference.step(np.zeros(6))
    assert stepper.state.shape[0] >= len(fixture.locators) + 1
    assert_same_state(compiled, reference)


# -- soft fingers -------------------------------------------------------------------------------------
def test_a_yaw_moment_on_a_mesh_box_is_resisted_by_its_soft_fingers_as_on_the_primitive_box(tmp_path: Path) -> None:
    """box-3-2-1-soft on its three base locators alone (μ = 0.25, e_r = 0.035 m), a pure yaw moment of 0.24 N·m.

    The file's closed forms: point contacts hold at most 0.2081 N·m; with the spin rows at least
    0.2688 N·m. So the primitive box and its 12-triangle mesh twin hold, with the same spin
    moments at each locator; the mesh twin without torsion arms turns.
    """
    text = (PROBLEMS / "box-3-2-1-soft.toml").read_text(encoding="utf-8")
    text = text[: text.index('[[locator]]\nname = "S1"')]  # B1, B2, B3 only
    (tmp_path / "box.toml").write_text(text)
    (tmp_path / "box12.stl").write_bytes(stl_bytes(*cell_surface(*box_cells((200.0, 100.0, 50.0), 1))))
    mesh_text = "\n".join(line for line in text.splitlines() if not line.startswith("face = "))
    mesh_text = mesh_text.replace(
        'shape = "box"\nsize = [0.20, 0.10, 0.05]', 'shape = "mesh"\nfile = "box12.stl"\nunits = "mm"'
    )
    assert mesh_text.count("torsion = 0.035") == 3
    (tmp_path / "mesh.toml").write_text(mesh_text)
    (tmp_path / "point.toml").write_text(mesh_text.replace("torsion = 0.035\n", ""))
    yaw = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.24])
    sims = {}
    for name in ("box", "mesh", "point"):
        sims[name] = Simulator(load(tmp_path / f"{name}.toml"))
        sims[name].run(0.2, yaw)
    box, mesh = sims["box"].contacts(), sims["mesh"].contacts()
    for sim in (sims["box"], sims["mesh"]):
        assert np.abs(sim.twist).max() <= 1e-9  # held
    spins = np.array([r.spin_moment_Nm for r in mesh])
    np.testing.assert_allclose(spins, [r.spin_moment_Nm for r in box], rtol=0, atol=1e-9)
    np.testing.assert_allclose([r.normal_force_N for r in mesh], [r.normal_force_N for r in box], rtol=0, atol=1e-9)
    assert np.abs(spins).min() > 0.01  # every base locator takes a share of the yaw
    assert sims["point"].twist[5] > 0.1  # without the spin rows 0.24 N·m is beyond what friction holds
    assert all(r.spin_moment_Nm == 0.0 for r in sims["point"].contacts())
