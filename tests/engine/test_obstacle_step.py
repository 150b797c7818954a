"""The compiled step with active obstacle contacts against the NumPy reference (tests/engine/reference_step.py)."""

import textwrap

import numpy as np
import pytest
from reference_step import reference_step

import fixplan
from fixplan.engine.simulator import Simulator

BOX_ON_PLATE = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "box-on-plate"
    [workpiece]
    shape = "box"
    size = [0.2, 0.1, 0.05]
    mass = 2.0
    start = { position = [0.0, 0.0, 0.0251], rpy_deg = [0.0, 0.0, 0.0] }
    [[locator]]
    name = "E1"
    position = [-0.1011, 0.0, 0.025]
    radius = 0.001
    friction = 0.3
    [[obstacle]]
    name = "plate"
    shape = "box"
    size = [0.4, 0.3, 0.02]
    pose = { position = [0.0, 0.0, -0.01], rpy_deg = [0.0, 0.0, 0.0] }
    friction = 0.4
    [[obstacle]]
    name = "wall"
    shape = "plane"
    point = [0.1001, 0.0, 0.0]
    normal = [-1.0, 0.0, 0.0]
    friction = 0.2
    """
)

RECT_ON_LINE = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "rect-on-line"
    dimension = 2
    [workpiece]
    shape = "rectangle"
    size = [0.2, 0.1]
    mass = 1.0
    start = { position = [0.0, 0.0501], angle_deg = 0.0 }
    [[locator]]
    name = "S"
    position = [-0.1011, 0.05]
    radius = 0.001
    friction = 0.3
    [[obstacle]]
    name = "floor"
    shape = "line"
    point = [0.0, 0.0]
    normal = [0.0, 1.0]
    friction = 0.4
    [[obstacle]]
    name = "block"
    shape = "rectangle"
    size = [0.1, 0.2]
    pose = { position = [0.1501, 0.1], angle_deg = 0.0 }
    """
)


@pytest.mark.parametrize("text", [BOX_ON_PLATE, RECT_ON_LINE], ids=["3d-plate-and-wall", "2d-line-and-block"])
def test_compiled_step_with_obstacles_matches_numpy_reference(text, rng):
    """Within 0.1 mm of a plate (or line) and a wall, pushed at random: same active set, impulses and twist."""
    f = fixplan.loads(text)
    sim = Simulator(f, tolerance=1e-12)
    d = f.dimension
    k_loc = len(f.locators)
    hits = 0
    for _trial in range(6):
        twist = rng.normal(size=6 if d == 3 else 3) * 0.05
        wrench = rng.normal(size=6 if d == 3 else 3) * np.r_[[5.0] * d, [0.2] * (3 if d == 3 else 1)]
        sim.set_state(f.start, twist)
        P_before, act_before = sim._P.copy(), sim._active.copy()
        f_ext, tau = sim._external(wrench)
        margin = sim.margin_m + 2 * sim.dt * (np.linalg.norm(twist[:d]) + np.linalg.norm(twist[d:]) * sim._bound)
        pose_ref, nu_ref, P_ref, act_ref, _err, _ = reference_step(
            f, f.start, twist, P_before, act_before, f_ext, tau, sim.dt, sim.restitution, margin, 1e-12, 2000
        )
        sim.step(wrench)
        assert np.array_equal(sim._active, act_ref)
        assert np.allclose(sim._P, P_ref, atol=1e-9 * max(1.0, np.abs(P_ref).max()))
        assert np.allclose(sim.twist, nu_ref, atol=1e-9)
        hits += int(act_ref[k_loc:].sum())
    assert hits > 0  # obstacle contacts were active
