"""The compiled step against the NumPy reference, and the simulator's basic contract."""

import math

import numpy as np
import pytest
from conftest import PROBLEMS
from reference_step import reference_step

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.errors import InputError
from fixplan.spatial import Pose


@pytest.mark.parametrize(
    "name", ["box-3-2-1.toml", "box-3-2-1-soft.toml", "rect-3.toml", "cylinder-5.toml", "polygon-2d.toml"]
)
def test_compiled_step_matches_numpy_reference(name, rng):
    f = fixplan.load(PROBLEMS / name)
    sim = Simulator(f, tolerance=1e-12)
    d = f.dimension
    for _trial in range(4):
        # a pose near the start with a random twist and push, so some contacts open and some slide
        twist = rng.normal(size=6 if d == 3 else 3) * 0.05
        wrench = rng.normal(size=6 if d == 3 else 3) * np.r_[[5.0] * d, [0.2] * (3 if d == 3 else 1)]
        sim.set_state(f.start, twist)
        P_before, act_before = sim._P.copy(), sim._active.copy()
        f_ext, tau = sim._external(wrench)
        margin = sim.margin_m + 2 * sim.dt * (np.linalg.norm(twist[:d]) + np.linalg.norm(twist[d:]) * sim._bound)
        pose_ref, nu_ref, P_ref, act_ref, err_ref, _ = reference_step(
            f, f.start, twist, P_before, act_before, f_ext, tau, sim.dt, sim.restitution, margin, 1e-12, 2000
        )
        sim.step(wrench)
        assert np.array_equal(sim._active, act_ref)
        assert np.allclose(sim._P, P_ref, atol=1e-9 * max(1.0, np.abs(P_ref).max()))
        assert np.allclose(sim.twist, nu_ref, atol=1e-9)
        if sim.last.penetration_m == 0.0:  # no post-stabilisation happened: poses agree exactly
            assert np.allclose(sim.pose.p_world, pose_ref.p_world, atol=1e-12)
            assert np.allclose(sim.pose.R_world_body, pose_ref.R_world_body, atol=1e-12)


def test_explicit_contacts_only_is_refused():
    f = fixplan.load(PROBLEMS / "peg-hole-mid.toml")
    with pytest.raises(InputError, match="no geometry to simulate"):
        Simulator(f)


def test_resting_box_normal_forces_carry_its_weight():
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    sim.run(0.05)
    reports = {c.name: c for c in sim.contacts()}
    total = sum(c.force_world for c in reports.values())
    assert np.allclose(total, [0, 0, 2.0 * 9.81], atol=1e-6)
    assert {n for n, c in reports.items() if c.mode != "open"} == {"B1", "B2", "B3"}
    assert all(reports[n].mode == "sticking" for n in ("B1", "B2", "B3"))


def test_initial_penetration_at_rest_is_removed_and_reported():
    """A box started 1 mm into its base locators is pushed out by post-stabilisation, and the depth is reported."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    start = f.start
    sim.set_state(Pose(start.R_world_body, start.p_world - np.array([0.0, 0.0, 1e-3])))
    sim.run(0.01)
    assert sim.max_penetration_m == pytest.approx(1e-3, rel=1e-6)
    gaps = {c.name: c.gap_m for c in sim.contacts()}
    assert min(gaps["B1"], gaps["B2"], gaps["B3"]) >= -1e-9
    assert abs(sim.twist).max() < 1e-6  # positions only: no velocity (energy) injected


def test_compiled_run_records_the_last_step_and_true_solver_figures():
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    traj = sim.run(0.015, [3.0, 0, 0, 0, 0, 0], record_every=10)
    assert traj.time_s == pytest.approx([0.0, 0.01, 0.015])
    assert sim.last.iterations >= 1 and sim.last.error > 0
    assert sim.time_s == pytest.approx(0.015)


def test_contact_report_before_any_step_has_the_exact_gaps():
    """`simulate --duration 0` printed every gap as 0 (the arrays before a step): a report is true
    from the start. The default box rests on B1-B3 (gap 0) with S1, S2, E1 open by their start gaps."""
    import fixplan
    from fixplan.engine.simulator import Simulator
    from fixplan.locating import locator_contact

    fx = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(fx)
    exact = {loc.name: locator_contact(fx.workpiece, fx.start, loc).gap_m for loc in fx.locators}
    reported = {c.name: c.gap_m for c in sim.contacts()}
    assert reported == pytest.approx(exact, abs=1e-15)
    assert min(exact[n] for n in ("S1", "S2", "E1")) > 1e-3


def _twin_runs(fixture, pose, schedule, duration, com_b=None):
    """The same run compiled end to end and stepped from Python (the schedule as a callable)."""
    sims = []
    for _ in range(2):
        sim = Simulator(fixture)
        if com_b is not None:  # an off-centre mass (no 3D shape has one): exercises the moment transfer
            sim._com_b = np.asarray(com_b, dtype=float)
        sim.set_state(pose)
        sims.append(sim)
    compiled = sims[0].run(duration, schedule, record_every=1)
    python = sims[1].run(duration, lambda t, s: schedule(t, s), record_every=1)
    return sims, compiled, python


@pytest.mark.parametrize("com_b", [None, [0.01, -0.02, 0.005]])
def test_compiled_loop_equals_python_stepping_3d(com_b):
    """The compiled loop and Simulator.step from Python give one trajectory (to 1e-12): the box
    pushed into its six locators, then pulled away and pushed sideways (contacts open, slide, close)."""
    from fixplan.engine.simulator import WrenchSchedule

    f = fixplan.load(fixplan.default_fixture_path())
    push = -5.0 * np.ones(3) / math.sqrt(3.0)
    schedule = WrenchSchedule(
        [0.0, 0.05, 0.08], [[*push, 0, 0, 0], [0.0, 3.0, 25.0, 0.05, 0, 0], [-8.0, 0.0, 0.0, 0, 0, 0.2]]
    )
    (a, b), ta, tb = _twin_runs(f, f.goal, schedule, 0.12, com_b)
    assert len(ta.time_s) == len(tb.time_s) == 121
    assert np.allclose(ta.time_s, tb.time_s, rtol=0, atol=1e-15)
    for key in ("position", "orientation", "velocity", "gap"):
        assert np.allclose(getattr(ta, key), getattr(tb, key), rtol=0, atol=1e-12), key
    assert np.allclose(ta.normal_force, tb.normal_force, rtol=0, atol=1e-9)
    assert np.array_equal(ta.iterations, tb.iterations)
    assert np.allclose(a._P, b._P, rtol=0, atol=1e-12) and np.array_equal(a._active, b._active)
    assert a.max_penetration_m == pytest.approx(b.max_penetration_m, abs=1e-15)
    assert np.ptp(ta.velocity[:, 2]) > 0.01  # it did move: the pull lifts it off the base


def test_compiled_loop_equals_python_stepping_2d():
    """2D runs are compiled too, and agree with per-step stepping (polygon with an off-centre mass)."""
    from fixplan.engine.simulator import WrenchSchedule

    f = fixplan.load(PROBLEMS / "polygon-2d.toml")
    schedule = WrenchSchedule([0.0, 0.04], [[1.0, -2.0, 0.02], [-3.0, 0.5, -0.05]])
    (a, b), ta, tb = _twin_runs(f, f.start, schedule, 0.08)
    for key in ("time_s", "position", "orientation", "velocity", "gap"):
        assert np.allclose(getattr(ta, key), getattr(tb, key), rtol=0, atol=1e-12), key
    assert np.array_equal(ta.iterations, tb.iterations)
    assert np.allclose(a.twist, b.twist, rtol=0, atol=1e-12)


def test_wrench_schedule_is_checked():
    from fixplan.engine.simulator import WrenchSchedule

    with pytest.raises(InputError, match="increasing times"):
        WrenchSchedule([0.0, 0.0], np.zeros((2, 6)))
    with pytest.raises(InputError, match="n times and n wrenches"):
        WrenchSchedule([0.0, 1.0], np.zeros((3, 6)))
    f = fixplan.load(fixplan.default_fixture_path())
    with pytest.raises(InputError, match="6 numbers per wrench"):
        Simulator(f).run(0.01, WrenchSchedule([0.0], np.zeros((1, 3))))


def test_body_state_is_a_copy_of_the_state():
    """``body_state`` reports the pose and twist, and writing into it leaves the simulator unchanged."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    twist = np.array([0.01, -0.02, 0.0, 0.1, 0.0, -0.2])
    sim.set_state(f.start, twist)
    b = sim.body_state
    assert np.array_equal(b.R_world_body, sim.pose.R_world_body)
    assert np.array_equal(b.p_world, sim.pose.p_world)
    assert np.array_equal(np.concatenate([b.v_com_world, b.omega_world]), twist)
    assert np.allclose(sim.com_world, b.p_world + b.R_world_body @ sim.com_body, atol=0)
    b.R_world_body[:] = 0.0
    b.p_world[:] = 0.0
    b.v_com_world[:] = 0.0
    assert np.array_equal(sim.pose.R_world_body, f.start.R_world_body)
    assert np.array_equal(sim.twist, twist)
