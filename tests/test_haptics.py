"""The simulated haptic loop: passivity check, what the user feels, the loop's timing record."""

import numpy as np
import pytest

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.errors import InputError
from fixplan.haptics import HapticLoop, SimulatedDevice, VirtualCoupling, check_passivity


def test_passivity_condition_is_enforced():
    """Colgate & Schenkel: b > K T / 2 + |B|."""
    assert check_passivity(K=1000.0, B=2.0, T=1e-3, b=3.0) == pytest.approx(3.0 - 0.5 - 2.0)
    with pytest.raises(InputError, match="not passive"):
        check_passivity(K=5000.0, B=2.0, T=1e-3, b=3.0)  # 2.5 + 2 = 4.5 > 3
    with pytest.raises(InputError, match="not passive"):
        VirtualCoupling(1000.0, 8.0, 1.0, 0.01, 1e-3, device_damping=8.0, device_damping_rot=0.08)


def test_device_saturates_displayed_force():
    dev = SimulatedDevice(6)
    shown = dev.set_force_and_torque([300.0, 400.0, 0.0, 0.0, 0.0, 10.0])
    assert np.linalg.norm(shown[:3]) == pytest.approx(dev.specs.max_force_N)
    assert np.allclose(shown[:3] / np.linalg.norm(shown[:3]), [0.6, 0.8, 0.0])
    assert shown[5] == pytest.approx(dev.specs.max_torque_Nm)


def test_user_feels_the_locator_reaction():
    """Pushing the located box into E1 through the coupling: the felt force settles at the push (the box is held)."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    sim.set_state(f.goal)
    dev = SimulatedDevice(6, x0=np.concatenate([f.goal.p_world, np.zeros(3)]))
    coupling = VirtualCoupling(
        1000.0, 2.0, 20.0, 0.02, 1e-3, device_damping=dev.specs.physical_damping_Ns_per_m, device_damping_rot=0.08
    )
    loop = HapticLoop(sim, dev, coupling)
    push = np.array([-10.0, 0, 0, 0, 0, 0])
    rec = loop.run(1.0, lambda t, d: push)
    # quasi-static end: the device is held by the coupling, the user feels +10 N back
    assert rec.felt_wrench[-1][0] == pytest.approx(10.0, rel=1e-3)
    assert "E1" in rec.active_contacts[-1]
    assert np.linalg.norm(rec.workpiece_position[-1] - f.goal.p_world) < 1e-6  # the box stays located
    assert len(rec.compute_s) == 1000 and rec.mean_compute_s > 0


def test_compiled_coupling_matches_the_python_formula(rng):
    """The tick's compiled coupling equals K (x_d − x_w) + B (ẋ_d − ẋ_w) computed from the workpiece coordinates."""
    from fixplan.haptics import _kernels
    from fixplan.spatial import Pose

    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    dev = SimulatedDevice(6)
    coupling = VirtualCoupling(1000.0, 2.0, 20.0, 0.02, 1e-3, device_damping=8.0, device_damping_rot=0.08)
    loop = HapticLoop(sim, dev, coupling)
    sim.set_state(Pose.from_rpy_deg(f.start.p_world + 0.01, [3.0, -2.0, 10.0]), rng.normal(size=6))
    x_d, v_d = rng.normal(size=6) * 0.01, rng.normal(size=6)
    x_w, v_w = loop.workpiece_coordinates()
    expected = coupling.wrench(x_d - x_w, v_d - v_w, 3)
    b = sim.body_state
    got = _kernels.coupling3(
        b.R_world_body, b.p_world, sim.com_body, b.v_com_world, b.omega_world, loop._R0, x_d, v_d, loop._K, loop._B
    )
    assert np.allclose(got, expected, atol=1e-12)


def test_compiled_device_coordinates_match_the_numpy_ones(rng):
    """The interactive loop's compiled device coordinates equal ``workpiece_coordinates`` (origin, rotation vector, rates)."""
    from fixplan.haptics.coordinates import coordinates_from_pose, pose_from_coordinates, workpiece_coordinates
    from fixplan.spatial import Pose

    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    R0 = f.start.R_world_body
    for _ in range(5):
        sim.set_state(Pose.from_rpy_deg(f.start.p_world + 0.01 * rng.normal(size=3), rng.normal(size=3) * 20.0),
                      rng.normal(size=6))  # fmt: skip
        x, v = workpiece_coordinates(sim, R0)
        x_c, v_c = workpiece_coordinates(sim, R0, compiled=True)
        np.testing.assert_allclose(x_c, x, atol=1e-14)
        np.testing.assert_allclose(v_c, v, atol=1e-14)
        # the body origin's velocity is the centre of mass's plus ω × (p − c)
        twist = sim.twist
        np.testing.assert_allclose(v[:3], twist[:3] + np.cross(twist[3:], sim.pose.p_world - sim.com_world), atol=1e-14)
        # and the coordinates invert to the pose
        back = pose_from_coordinates(x, R0, 3)
        np.testing.assert_allclose(back.R_world_body, sim.pose.R_world_body, atol=1e-12)
        np.testing.assert_allclose(coordinates_from_pose(back, R0), x, atol=1e-12)


def test_tick_applies_the_coupling_of_the_rotating_part(rng):
    """The wrench a tick applies is K (x_d − x_w) + B (ẋ_d − ẋ_w) of the part's state before the step (spinning part)."""
    from fixplan.spatial import Pose

    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    dev = SimulatedDevice(6, x0=np.concatenate([f.start.p_world + 0.05, np.zeros(3)]))
    coupling = VirtualCoupling(1000.0, 2.0, 20.0, 0.02, 1e-3, device_damping=8.0, device_damping_rot=0.08)
    loop = HapticLoop(sim, dev, coupling)
    # lifted clear of the locators and spinning about z: the body origin (the box centre) moves
    sim.set_state(Pose.from_rpy_deg(f.start.p_world + [0, 0, 0.05], [0, 0, 4.0]), [0.1, -0.2, 0.0, 0.3, -0.1, 1.0])
    x_w, v_w = loop.workpiece_coordinates()
    expected = coupling.wrench(dev.position() - x_w, dev.velocity() - v_w, 3)
    w_c, _, _ = loop.tick(np.zeros(6))
    assert np.allclose(w_c, expected, atol=1e-12)


def test_loop_refuses_a_coupling_checked_with_more_damping_than_the_device_has():
    from fixplan.haptics import DeviceSpecs

    f = fixplan.load(fixplan.default_fixture_path())
    specs = DeviceSpecs(
        max_force_N=20.0,
        max_torque_Nm=1.0,
        max_stiffness_N_per_m=5000.0,
        max_damping_Ns_per_m=50.0,
        workspace_radius_m=0.5,
        physical_damping_Ns_per_m=0.0,
    )
    dev = SimulatedDevice(6, specs=specs)
    coupling = VirtualCoupling(1000.0, 2.0, 20.0, 0.02, 1e-3, device_damping=8.0, device_damping_rot=0.08)
    with pytest.raises(InputError, match="device damping"):
        HapticLoop(Simulator(f), dev, coupling)
