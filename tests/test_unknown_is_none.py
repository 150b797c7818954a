"""Results say None where they do not know, and a measured value where they do (never a made-up 0)."""

import numpy as np
import pytest
from conftest import box_on_three_supports as box_on_supports

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.errors import SolverError
from fixplan.haptics import HapticLoop, SimulatedDevice, VirtualCoupling
from fixplan.jamming import backends, can_wedge, wedge_force
from fixplan.jamming.cvx import least_residual
from fixplan.planner.verify import loop_measures
from tests.test_jamming import peg


def test_cvx_cone_violation_is_measured_or_none(monkeypatch):
    """cvxpy path: the cone violation is the worst of −λ_n, ‖λ_t‖ − μ λ_n and ‖ŵ + Jᵀλ‖ − t at its answer."""
    f = box_on_supports(mu=0.3, mass=2.0)
    cs = fixplan.contact_set(f)
    w_hat = np.array([2.0, 1.0, -2.0 * 9.81, 0.05, -0.02, 0.01])
    eye = np.eye(6)
    sol, lam = least_residual(cs, w_hat, eye, eye)
    assert sol.solved and sol.cone_violation is not None
    worst = float(np.linalg.norm(w_hat + cs.J.T @ lam)) - sol.value
    for k in range(3):  # three point contacts (normal, two tangents), computed here independently
        n, t1, t2 = lam[3 * k : 3 * k + 3]
        worst = max(worst, -n, float(np.hypot(t1, t2)) - 0.3 * n)
    assert sol.cone_violation == pytest.approx(max(worst, 0.0), abs=1e-15)
    assert sol.cone_violation < 1e-7  # and Clarabel met its cones

    import cvxpy as cp

    monkeypatch.setattr(cp.Problem, "solve", lambda self, **kw: None)  # the solver gives no answer
    sol, _ = least_residual(cs, w_hat, eye, eye)
    assert not sol.solved and sol.cone_violation is None


def test_clarabel_cone_violation_is_the_programs_own():
    """Clarabel path: the reported violation is the program's cones evaluated at the returned x."""
    from fixplan.jamming.wedge import wedge_program

    prog = wedge_program(fixplan.contact_set(box_on_supports()))
    sol = backends.ClarabelProgram(prog).solve(prog.b)
    assert sol.solved and sol.cone_violation == prog.cone_violation(sol.x)


def test_wedge_force_unknown_is_none_and_can_wedge_says_so(monkeypatch):
    """Whitney: a two-point peg wedges iff depth < 2 r μ; an unsolved program is None, not 'no wedging'."""
    r, mu = 0.01, 0.3
    assert wedge_force(fixplan.contact_set(peg(0.5 * 2 * r * mu, r, mu))) > 0.1
    assert wedge_force(fixplan.contact_set(peg(3 * 2 * r * mu, r, mu))) == pytest.approx(0.0, abs=1e-7)
    real_solve = backends.ClarabelProgram.solve

    def unsolved(self, b):
        s = real_solve(self, b)
        return backends.ConeSolution(s.x, s.value, False, "MaxIterations", s.iterations, s.solve_time_s, None)

    monkeypatch.setattr(backends.ClarabelProgram, "solve", unsolved)
    cs = fixplan.contact_set(peg(0.5 * 2 * r * mu, r, mu))
    assert wedge_force(cs) is None
    with pytest.raises(SolverError, match="wedging program was not solved"):
        can_wedge(cs)


def test_failed_local_solves_counted_by_step_unknown_after_compiled_run():
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    sim.set_state(f.goal)
    info = sim.step(np.array([-10.0, -10.0, -10.0, 0, 0, 0]))
    assert len(info.active) == 6
    assert info.failed_local_solves == 0  # the exact local solvers (closed-form cone projections) never fail
    sim.run(0.01, np.array([-10.0, -10.0, -10.0, 0, 0, 0]))
    assert sim.last.failed_local_solves is None  # the compiled loop does not count them


def test_loop_timing_unknown_without_ticks():
    """No tick ran: tick times and felt force are None; after ticks they are the record's own statistics."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    sim.set_state(f.goal)
    dev = SimulatedDevice(6, x0=np.concatenate([f.goal.p_world, np.zeros(3)]))
    coupling = VirtualCoupling(1000.0, 2.0, 20.0, 0.02, 1e-3, device_damping=8.0, device_damping_rot=0.08)
    loop = HapticLoop(sim, dev, coupling)
    rec = loop.run(0.0, lambda t, d: np.zeros(6))
    assert rec.mean_compute_s is None and rec.max_compute_s is None
    m = loop_measures(rec, sim, 0)
    assert m["tick_mean_us"] is None and m["tick_max_us"] is None and m["felt_force_max_N"] is None
    assert m["deadline_misses"] == 0  # zero ticks, zero of them late: known
    rec = loop.run(0.005, lambda t, d: np.array([-5.0, 0, 0, 0, 0, 0]))
    m = loop_measures(rec, sim, 0)
    assert m["tick_mean_us"] == pytest.approx(np.mean(rec.compute_s) * 1e6)
    assert m["tick_max_us"] == pytest.approx(max(rec.compute_s) * 1e6)
    assert m["felt_force_max_N"] == pytest.approx(max(np.linalg.norm(w[:3]) for w in rec.felt_wrench))


def test_session_stats_unknown_before_the_first_tick():
    from fixplan.interactive.session import HapticSession

    box = fixplan.load(fixplan.default_fixture_path())
    s = HapticSession(box, None, realtime=False, synchronous=False, guidance=False)
    st = s.stats()
    assert st.ticks == 0 and st.tick_mean_us is None and st.tick_max_us is None and st.late_p99_us is None
    assert s.final_stats().to_json()["tick_mean_us"] is None


def test_diverged_verification_has_no_loop_measures(monkeypatch):
    """A load that diverges reports None for what the unfinished loop never measured, not 0."""
    from fixplan.errors import SolverError
    from fixplan.haptics import HapticLoop
    from fixplan.planner.verify import verify

    def diverge(self, *args, **kwargs):
        raise SolverError("NSGS produced a non-finite state")

    monkeypatch.setattr(HapticLoop, "run", diverge)
    box = fixplan.load(fixplan.default_fixture_path())
    v = verify(box, frozenset(), [])
    assert not v.passed and "diverged" in v.reason
    assert v.deadline_misses is None and v.tick_mean_us is None and v.tick_max_us is None
    assert v.unconverged_steps is None and v.max_solver_error is None and v.felt_force_max_N is None
    doc = v.to_json()
    assert doc["unconverged_steps"] is None and doc["max_solver_error"] is None


def test_solver_error_over_ticks_is_the_worst_step_error(monkeypatch):
    """After ticks: the worst FCLib residual the steps reached; before any: None."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f)
    sim.set_state(f.goal)
    dev = SimulatedDevice(6, x0=np.concatenate([f.goal.p_world, np.zeros(3)]))
    coupling = VirtualCoupling(1000.0, 2.0, 20.0, 0.02, 1e-3, device_damping=8.0, device_damping_rot=0.08)
    loop = HapticLoop(sim, dev, coupling)
    assert loop.run(0.0, lambda t, d: np.zeros(6)).max_solver_error is None
    errors = []
    original = Simulator.step

    def step(self, *args, **kwargs):
        info = original(self, *args, **kwargs)
        errors.append(info.error)
        return info

    monkeypatch.setattr(Simulator, "step", step)
    rec = loop.run(0.005, lambda t, d: np.array([-5.0, 0, 0, 0, 0, 0]))
    ticks = len(rec.compute_s)
    assert ticks == 5 and rec.max_solver_error == max(errors[-ticks:])  # (a warm-up step may precede the ticks)
