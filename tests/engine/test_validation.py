"""The engine against closed forms. Each docstring gives the closed form."""

import math

import numpy as np
import pytest
from conftest import box_on_three_supports

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.settings import STRICT
from fixplan.spatial import log_so3


def box_on_three(mu, gravity=(0.0, 0.0, -9.81), mass=2.0, dt=1e-3, tol=1e-10, e=0.0, torsion=0.0, extra=""):
    """The box on three supports with this module's solver settings (tight tolerance, no restitution)."""
    sim = {"timestep": dt, "tolerance": tol, "restitution": e}
    return box_on_three_supports(mu, mass=mass, gravity=gravity, torsion=torsion, simulation=sim, extra=extra)


def incline_gravity(theta_deg, g=9.81):
    th = math.radians(theta_deg)
    return (g * math.sin(th), 0.0, -g * math.cos(th))


def test_incline_stick_no_creep():
    """θ = 20°, μ = 0.5 > tan 20° = 0.364: the box sticks; it moves ≤ 1e-8 m in 2 s."""
    f = box_on_three(0.5, incline_gravity(20.0))
    sim = Simulator(f)
    p0 = sim.pose.p_world.copy()
    sim.run(2.0)
    assert np.linalg.norm(sim.pose.p_world - p0) <= 1e-8
    assert all(c.mode == "sticking" for c in sim.contacts())


def test_incline_slide_closed_form():
    """θ = 30°, μ = 0.3: v(t) = g (sin θ − μ cos θ) t to 1e-6 relative; lift-off ≤ 1e-7 m.

    The supports are fixed while the box slides over them, so the trailing support B1 unloads
    (its normal force reaches 0 at t ≈ 0.14 s and the box starts to tip about B2–B3): the closed
    form holds while all three carry load, so the run stops at 0.12 s."""
    th = math.radians(30.0)
    f = box_on_three(0.3, incline_gravity(30.0))
    sim = Simulator(f)
    traj = sim.run(0.12, record_every=10)
    a = 9.81 * (math.sin(th) - 0.3 * math.cos(th))
    for t, nu in zip(traj.time_s[1:], traj.velocity[1:], strict=True):
        assert nu[0] == pytest.approx(a * t, rel=1e-6)
    z = np.array(traj.position)[:, 2]
    assert np.max(np.abs(z - 0.025)) <= 1e-7
    assert all(c.mode == "sliding" for c in sim.contacts())


def test_spin_down_under_torsional_friction():
    """A ball spinning on one soft-finger locator under it: dω/dt = −μ e_r N / I, N = m g, I = 2/5 m R²."""
    mu, er, R, m = 0.4, 0.004, 0.05, 1.5
    f = fixplan.loads(
        f"""format = 1
[scene]
name = "spin"
[workpiece]
shape = "sphere"
radius = {R}
mass = {m}
start = {{ position = [0.0, 0.0, {R}] }}
[simulation]
tolerance = 1e-12
[[locator]]
name = "S"
position = [0.0, 0.0, 0.0]
friction = {mu}
torsion = {er}
"""
    )
    sim = Simulator(f)
    w0 = 3.0
    sim.set_state(f.start, [0, 0, 0, 0, 0, w0])
    traj = sim.run(0.2, record_every=10)
    alpha = mu * er * m * 9.81 / (0.4 * m * R * R)
    for t, nu in zip(traj.time_s[1:], traj.velocity[1:], strict=True):
        expected = max(w0 - alpha * t, 0.0)
        if expected > 0.05:
            assert nu[5] == pytest.approx(expected, rel=1e-6)
    assert {c.mode for c in sim.contacts()} <= {"sliding", "sticking", "rolling"}


def test_free_tumbling_conserves_angular_momentum():
    """No contact, no gravity: L = R I_b Rᵀ ω is conserved to 1e-10 over 10⁴ steps (intermediate-axis tumbling)."""
    f = fixplan.loads(
        """format = 1
[scene]
name = "tumble"
gravity = [0.0, 0.0, 0.0]
[workpiece]
shape = "box"
size = [0.3, 0.1, 0.05]
mass = 1.0
start = { position = [0.0, 0.0, 1.0] }
[[locator]]
name = "far"
position = [5.0, 5.0, 5.0]
friction = 0.1
"""
    )
    sim = Simulator(f, dt=1e-3)
    sim.set_state(f.start, [0.1, 0, 0, 0.05, 6.0, 0.02])
    Ib = f.workpiece.inertia_body

    def momentum():
        R = sim.pose.R_world_body
        return R @ Ib @ R.T @ sim.twist[3:]

    L0 = momentum()
    sim.run(10.0, record_every=1000)
    assert np.linalg.norm(momentum() - L0) <= 1e-10 * np.linalg.norm(L0)
    # and it really tumbled (the intermediate axis is unstable)
    assert np.linalg.norm(log_so3(sim.pose.R_world_body)) > 0.1


def test_located_box_pushed_into_six_locators():
    """Pushed into its six locators with 50 N: penetration ≤ 1e-6 m, contact forces balance push + gravity."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f, settings=STRICT.engine)  # NSGS residual 1e-10
    sim.set_state(f.goal)
    push = -50.0 * np.ones(3) / math.sqrt(3.0)
    sim.run(0.5, np.concatenate([push, np.zeros(3)]))
    assert sim.max_penetration_m <= 1e-6
    reports = sim.contacts()
    assert {c.name for c in reports if c.mode != "open"} == {"B1", "B2", "B3", "S1", "S2", "E1"}
    total_force = sum(c.force_world for c in reports)
    weight = np.array([0, 0, -2.0 * 9.81])
    assert np.linalg.norm(total_force + push + weight) <= 1e-6 * 50
    assert np.linalg.norm(sim.twist) <= 1e-9


@pytest.mark.parametrize("e", [0.5, 0.8])
def test_bounce_reaches_e_squared_h(e):
    """A ball dropped from height H on one locator rebounds to e² H (Newton restitution)."""
    H, R = 0.1, 0.02
    f = fixplan.loads(
        f"""format = 1
[scene]
name = "bounce"
[workpiece]
shape = "sphere"
radius = {R}
mass = 0.1
start = {{ position = [0.0, 0.0, {R + H}] }}
[simulation]
timestep = 1e-5
restitution = {e}
[[locator]]
name = "floor"
position = [0.0, 0.0, 0.0]
friction = 0.3
"""
    )
    sim = Simulator(f)
    traj = sim.run(0.5, record_every=10)
    z = np.array(traj.position)[:, 2] - R
    v = np.array(traj.velocity)[:, 2]
    first_up = int(np.argmax(v > 0))
    apex = z[first_up:][np.argmax(v[first_up:] <= 0)]
    assert apex == pytest.approx(e * e * H, rel=2e-3)


@pytest.mark.parametrize(
    ("mass", "dt", "mu"),
    [(1e-3, 1e-3, 0.3), (1e3, 1e-3, 0.3), (2.0, 1e-5, 0.3), (2.0, 1e-2, 0.3), (2.0, 1e-3, 2.0)],
)
def test_hard_cases_stay_finite(mass, dt, mu):
    """Extreme masses, steps and friction, with a redundant fourth support: no NaN, no blow-up."""
    extra = f'[[locator]]\nname = "B4"\nposition = [0.0, -0.03, 0.0]\nfriction = {mu}\n'
    f = box_on_three(mu, mass=mass, dt=dt, extra=extra)
    sim = Simulator(f)
    push = np.array([3.0 * mass * 9.81, 0.5 * mass * 9.81, 0.0, 0.0, 0.0, 0.01 * mass])
    traj = sim.run(min(0.3, 300 * dt), push, record_every=10)
    nu = np.array(traj.velocity)
    assert np.all(np.isfinite(nu)) and np.all(np.isfinite(np.array(traj.position)))
    assert np.abs(nu).max() < 100.0
    assert sim.max_penetration_m <= 1e-6


def test_painleve_rod_high_friction():
    """A long thin rod dragged along one end on a locator with μ = 2 (Painlevé-prone): finite, no blow-up."""
    f = fixplan.loads(
        """format = 1
[scene]
name = "rod"
[workpiece]
shape = "box"
size = [0.5, 0.01, 0.01]
mass = 0.5
start = { position = [0.0, 0.0, 0.1768], rpy_deg = [0.0, 45.0, 0.0] }
[[locator]]
name = "end"
position = [-0.1803, 0.0, -0.0036]
friction = 2.0
"""
    )
    sim = Simulator(f)
    sim.set_state(f.start, [-1.0, 0, 0, 0, 0, 0])
    traj = sim.run(0.3)
    nu = np.array(traj.velocity)
    assert np.all(np.isfinite(nu)) and np.abs(nu).max() < 50
