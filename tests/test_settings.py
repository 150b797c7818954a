"""Settings in one place: the profiles the code selects, and no stray thresholds elsewhere."""

import numpy as np
import pytest
from conftest import PROBLEMS

import fixplan
from fixplan import settings
from fixplan.engine.simulator import Simulator
from fixplan.errors import InputError
from fixplan.haptics.coordinates import coordinates_from_pose
from fixplan.haptics.rig import haptic_rig
from fixplan.jamming import classify


def test_unknown_profile_lists_the_known_ones():
    assert settings.profile("haptic") is settings.HAPTIC
    with pytest.raises(InputError, match="unknown settings profile 'fast'.*default, haptic, strict"):
        settings.profile("fast")


def test_the_settings_are_the_one_way_in():
    """``fixplan.tolerances`` and ``fixplan.Tolerances`` are gone; a fixture carries its profile's tolerances."""
    from pathlib import Path

    # the package's own folder (an import could be served by another checkout's editable install)
    assert not (Path(fixplan.__file__).parent / "tolerances.py").exists()
    assert "Tolerances" not in fixplan.__all__ and not hasattr(fixplan, "Tolerances")
    path = fixplan.default_fixture_path()
    assert fixplan.load(path).tolerances == settings.DEFAULT.tolerances
    assert fixplan.load(path, settings=settings.STRICT).tolerances == settings.STRICT.tolerances


def test_engine_settings_reach_the_simulator():
    """The haptic profile's engine is the loop's: a 1e-6 residual and 200 sweeps; explicit arguments win."""
    f = fixplan.load(fixplan.default_fixture_path())
    plain = Simulator(f)
    assert plain.tolerance == f.simulation.tolerance and plain.max_iterations == settings.DEFAULT.engine.max_iterations
    sim = Simulator(f, settings=settings.HAPTIC.engine)
    assert (sim.tolerance, sim.max_iterations) == (1e-6, 1000)
    assert Simulator(f, max_iterations=7, settings=settings.HAPTIC.engine).max_iterations == 7


def test_haptic_rig_follows_its_settings():
    """K = k·m, b = max(b_min, s (K T/2 + B)) (passive with safety s), operator PD m ω², 2 ζ ω m."""
    f = fixplan.load(fixplan.default_fixture_path())
    sim = Simulator(f, settings=settings.HAPTIC.engine)
    x0 = coordinates_from_pose(f.start, f.start.R_world_body)
    for rig_settings in (
        settings.HAPTIC.haptic,
        settings.HapticRigSettings(stiffness_per_kg=400.0, passivity_safety=3.0),
    ):
        rig = haptic_rig(f, sim, x0, 20.0, 2.0, rig_settings)
        c = rig.loop.coupling
        m = f.workpiece.mass_kg
        K = rig_settings.stiffness_per_kg * m
        B = rig_settings.damping_time_s * K
        assert c.K_lin == pytest.approx(K) and c.B_lin == pytest.approx(B)
        b = max(rig_settings.min_device_damping_Ns_per_m, rig_settings.passivity_safety * (K * sim.dt / 2 + B))
        assert c.device_damping == pytest.approx(b)
        assert c.margins[0] == pytest.approx(b - (K * sim.dt / 2 + B))  # Colgate–Schenkel margin
        w, z, m_dev = (
            rig_settings.operator_omega_radps,
            rig_settings.operator_damping_ratio,
            rig_settings.handle_mass_kg,
        )
        assert rig.kp[0] == pytest.approx(m_dev * w**2) and rig.kd[0] == pytest.approx(2 * z * w * m_dev)
        assert rig.loop.device.specs.max_force_N == pytest.approx(rig_settings.display_headroom * 20.0)


def test_strict_profile_tightens_the_closed_form_check():
    """Box on three supports, μ = 0.3: a push F < μ m g jams with zero residual; F > μ m g slides at (F − μ m g)/m.

    Under the strict profile the cone programs meet the closed form to 1e-8 of the push."""
    from conftest import box_on_three_supports as box_on_supports

    f = box_on_supports(mu=0.3, mass=2.0)
    strict = settings.STRICT.tolerances
    limit = 0.3 * 2.0 * 9.81
    r = classify(f, [0.9 * limit, 0, 0, 0, 0, 0], settings=settings.STRICT)[0]
    assert r.mode == "jammed" and r.margin <= strict.balance_rel * limit
    F = 2 * limit
    r = classify(f, [F, 0, 0, 0, 0, 0], settings=settings.STRICT)[0]
    assert r.mode == "slides"
    assert r.acceleration[0] == pytest.approx((F - limit) / 2.0, rel=1e-9)
    assert np.allclose(r.acceleration[1:], 0, atol=1e-10)


# -- no stray thresholds ---------------------------------------------------------------------------
# A threshold-looking literal is a float in [1e-11, 1e-3): a tolerance, a gap, a rate. Not counted:
# smaller ones (round-off guards such as 1e-300 or 1e-12 slack, far below any tolerance) and floors
# written as an argument of max()/min() (guards against dividing by zero, not thresholds).
# Allowed where they are, with the reason:
ALLOWED_MODULES = {
    "settings.py": "the settings themselves",
    "limits.py": "the accepted input ranges, one place already (docs/limits.md)",
    "spatial.py": "series switch points of SO(3) exp/log (mathematics, not settings)",
    "engine/": "constants compiled into numba kernels (numba freezes them); the engine's own numerics",
    "_kernels.py": "constants compiled into numba kernels: the same switch points as their Python twins",
    "fixture.py": "the fixture format's documented [simulation] defaults (docs: FIXTURE_FORMAT)",
    "model.py": "the fixture format's documented [simulation] defaults (docs: FIXTURE_FORMAT)",
    "generate.py": "the random fixture generator's distributions and exactness of what it generates",
    "present/": "figure and scene scales (display only)",
    "interactive/app.py": "the browser view's drawing scales (display only)",
}


def _threshold_literals(path):
    import ast

    tree = ast.parse(path.read_text())
    guarded = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("max", "min"):
            guarded.update(id(a) for a in node.args)
    for node in ast.walk(tree):
        if isinstance(node, ast.UnaryOp) and id(node) in guarded:
            guarded.add(id(node.operand))
    return [
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, float)
        and 1e-11 <= abs(node.value) < 1e-3
        and id(node) not in guarded
    ]


def test_no_threshold_literal_outside_settings():
    from pathlib import Path

    root = Path(fixplan.__file__).parent
    stray = []
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if any(rel.startswith(key) or rel.endswith(key) for key in ALLOWED_MODULES):
            continue
        stray += [f"fixplan/{rel}:{line}: {value!r}" for line, value in _threshold_literals(path)]
    assert not stray, "thresholds belong in fixplan/settings.py:\n" + "\n".join(stray)


def test_solver_options_only_in_settings():
    """IPOPT's options are built by PlannerSettings.ipopt_options, nowhere else."""
    import ast
    from pathlib import Path

    root = Path(fixplan.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.name == "settings.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Dict):
                keys = {k.value for k in node.keys if isinstance(k, ast.Constant)}
                if keys & {"constr_viol_tol", "print_level", "sb"}:  # IPOPT-only keys
                    found.append(f"{path.relative_to(root)}:{node.lineno}")
    assert not found, f"solver option dicts outside settings.py: {found}"
    options = settings.DEFAULT.planner.ipopt_options()
    assert options["tol"] == 1e-9 and options["max_iter"] == 150 and options["constr_viol_tol"] == 1e-10
    assert settings.DEFAULT.planner.ipopt_options(tol=1e-6, max_iter=3)["max_iter"] == 3


# -- a profile reaches every threshold that was once captured at import time -------------------------
def _search_with(**changes):
    from dataclasses import replace

    return settings.DEFAULT.with_(search=replace(settings.DEFAULT.search, **changes))


def test_search_slip_rel_comes_from_the_settings_passed():
    """Rolling about B1 (μ = 0.15) while the part already slips at B1: a slip twist ``(v, 0, ω)`` at B1
    slips there at the fraction ``r = v / (v + |ω| L)`` of its speed. B1 slides against that slip when
    ``search.slip_rel`` is below ``r`` and keeps sticking (the motion asked for) when above."""
    from fixplan.jamming.search import search_wrench

    fx = fixplan.load(PROBLEMS / "naive-order-jams.toml")
    cs = fixplan.contact_set(fx, "start", ["B1"])
    B1 = cs.contacts[0].point_world
    v, w = 0.01, -1.0
    r = v / (v + abs(w) * cs.max_lever_m)  # 0.11 (B1's tangent is 5° off x: slip 0.996 v)
    for slip_rel, role in ((r / 2, "sliding"), (2 * r, "sticking")):
        res = search_wrench(
            fx,
            [0.0, 0.0, -1.0],
            ["B1"],
            pose="start",
            at=B1,
            slip_twist=[v, 0.0, w],
            settings=_search_with(slip_rel=slip_rel),
        )
        assert res.contact_roles == {"B1": role}, slip_rel


def test_search_jam_margin_and_target_rel_come_from_the_settings_passed():
    """rect-3 sliding on B1, B2 at 1 m/s²: the push found is certified ``search.jam_margin_rel`` from static
    balance (the classifier measures at least that, and pressing the contacts less hard buys it), and a margin
    target 0.1 % above the best τ* counts as met only when ``search.target_rel`` allows 0.1 %."""
    from fixplan.jamming.search import search_wrench

    fx = fixplan.load(PROBLEMS / "rect-3.toml")
    args = (fx, [1.0, 0.0, 0.0], ["B1", "B2"])
    best = search_wrench(*args, limit_fraction=1.0)
    assert best.found and best.jam_margin_rel is not None and best.jam_margin_rel < 0.2
    far = search_wrench(*args, limit_fraction=1.0, settings=_search_with(jam_margin_rel=0.2))
    assert far.found and far.jam_margin_rel >= 0.2 * (1 - 1e-6)
    assert far.margin_N < best.margin_N
    with pytest.raises(InputError, match="jam_margin_rel must lie in"):
        search_wrench(*args, settings=_search_with(jam_margin_rel=1.5))
    target = best.margin_N * (1 + 1e-3)
    tight = search_wrench(*args, limit_fraction=1.0, min_margin_N=target)
    loose = search_wrench(*args, limit_fraction=1.0, min_margin_N=target, settings=_search_with(target_rel=1e-2))
    assert tight.margin_target_met is False and "not met" in tight.reason
    assert loose.margin_target_met is True and loose.margin_N == pytest.approx(best.margin_N, rel=1e-9)


def test_witness_settings_reach_the_classifier_and_its_witness_search():
    """The box pushed along +x on its base slides (Theorem 1's witness); with ``witness.root_rel = 0`` (no
    Newton root is exact) or ``witness.normal_rel = 0`` (no kept contact's normal rate is exactly 0) the same
    witness search accepts none, and the classifier cannot name the motion."""
    from dataclasses import replace

    from fixplan.jamming.classify import Classifier

    fx = fixplan.load(PROBLEMS / "box-3-2-1.toml")
    cs = fixplan.contact_set(fx, "start", ["B1", "B2", "B3"])
    w = [30.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert Classifier(cs, fx.gravity_wrench()).classify(w).mode == "slides"
    for change in ({"root_rel": 0.0}, {"normal_rel": 0.0}):
        witness = replace(settings.DEFAULT.witness, **change)
        clf = Classifier(cs, fx.gravity_wrench(), witness=witness)
        assert clf._witness.settings is witness
        assert clf.classify(w).mode == "indeterminate", change


def test_planner_settings_reach_the_clearances_and_the_friction_grid():
    """``solve(settings=)``: the friction-robustness grid is the settings' (0.5 on the default grid, 0.07 on
    (0.05, 0.07)), and a planner given no clearances to try says so."""
    from dataclasses import replace

    from fixplan.errors import SolverError
    from fixplan.locating import start_state
    from fixplan.planner.solve import Planner, solve

    fx = fixplan.load(PROBLEMS / "gen-plate-2d-s2026-000.toml")
    nominal = solve(fx, run_verification=False)
    assert nominal.friction_robustness == [0.5, 0.5]
    grid = settings.HAPTIC.with_(planner=replace(settings.HAPTIC.planner, robust_grid=(0.05, 0.07)))
    assert solve(fx, run_verification=False, settings=grid).friction_robustness == [0.07, 0.07]
    none = settings.DEFAULT.with_(planner=replace(settings.DEFAULT.planner, clearances_m=()))
    with pytest.raises(SolverError, match="planner.clearances_m is empty"):
        Planner(fx, settings=none).plan_from(fx.start, start_state(fx))


# -- the caller's profile reaches the run: the planner's, the executor's and the insertion's searches -----
def _custom_profile():
    """The haptic profile with a headroom of 0.7 (0.8 by default) and a wider contact gap: a profile no
    module-level default equals, so a run that reads the default instead shows it."""
    from dataclasses import replace

    return settings.HAPTIC.with_(
        name="custom",
        search=replace(settings.HAPTIC.search, limit_fraction=0.7),
        execution=replace(settings.HAPTIC.execution, contact_gap_m=3e-6),
    )


def _record_searches(monkeypatch):
    """Every wrench search's ``settings`` (``search_wrench`` goes through ``search_wrench_in`` too, and
    ``jamming.push.push_at``, which imported it by name)."""
    import fixplan.jamming.push as push_module
    import fixplan.jamming.search as search_module

    seen = []
    original = search_module.search_wrench_in

    def recording(*args, **kwargs):
        seen.append(kwargs.get("settings"))
        return original(*args, **kwargs)

    monkeypatch.setattr(search_module, "search_wrench_in", recording)
    monkeypatch.setattr(push_module, "search_wrench_in", recording)
    return seen


def test_solve_and_verify_search_with_the_callers_settings(monkeypatch):
    """``solve(settings=custom)`` on a 2D plate: every push the planner prices and the executor commands is
    searched with ``custom`` (before, they ran with the default profile's search settings), and the
    executor's headroom is ``custom.search.limit_fraction`` (0.7, not the default 0.8)."""
    from fixplan.planner.solve import solve

    custom = _custom_profile()
    seen = _record_searches(monkeypatch)
    result = solve(fixplan.load(PROBLEMS / "gen-plate-2d-s2026-000.toml"), settings=custom)
    assert result.status == "planned", result.reason
    assert seen and all(s is custom for s in seen), {getattr(s, "name", s) for s in seen}
    v = result.verification
    assert v.limit_fraction == 0.7 and v.ticks_above_fraction is not None


def test_the_executor_holds_its_profiles_numbers():
    """An executor given a profile takes its execution settings, headroom and pseudo-inverse cut-off from it;
    its own ``settings`` still override the execution group."""
    from dataclasses import replace

    from fixplan.planner.execute import ExecutionSettings, Executor

    fx = fixplan.load(PROBLEMS / "rect-3.toml")
    custom = _custom_profile().with_(numerics=replace(settings.HAPTIC.numerics, rcond=1e-9))
    ex = Executor(fx, frozenset(), [], profile=custom)
    assert ex.settings is custom.execution and ex.limit_fraction == 0.7 and ex.rcond == 1e-9
    own = ExecutionSettings(speed_mps=0.02)
    assert Executor(fx, frozenset(), [], own, profile=custom).settings is own
    F_cap = 0.7 * ex.F_max  # the hold push keeps the profile's headroom
    assert np.linalg.norm(ex.hold_wrench(fx.goal)[:2]) <= F_cap * (1 + 1e-9)


def test_insertion_plans_and_runs_with_the_callers_settings(monkeypatch):
    """``solve(settings=custom)`` on two pins: the insertion's pushes are searched with ``custom`` (before,
    ``solve_insertion`` planned with the default profile), the run senses contacts and rest with its
    execution settings, and its headroom is ``custom``'s."""
    import fixplan.planner.insertion as insertion
    from fixplan.planner.solve import solve

    custom = _custom_profile()
    seen = _record_searches(monkeypatch)
    runs = []

    class Recorded(insertion.InsertionRun):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            runs.append(self)

    monkeypatch.setattr(insertion, "InsertionRun", Recorded)
    result = solve(fixplan.load(PROBLEMS / "housing-2-pins-load.toml"), settings=custom)
    assert result.status == "planned", result.reason
    assert seen and all(s is custom for s in seen)
    assert len(runs) == 1 and runs[0].execution is custom.execution
    assert result.verification.limit_fraction == 0.7


# The run-time modules of solve and verify read no threshold of the default profile: the caller's
# settings are threaded down, and DEFAULT appears only as the default value of a parameter.
RUN_TIME_GROUPS = {
    "planner/execute.py": ("search", "execution", "planner", "policy"),
    "planner/insertion.py": ("search", "execution", "insertion"),
    "planner/verify.py": ("search", "execution", "verification"),
    "planner/solve.py": ("search", "execution", "planner", "policy"),
    "planner/segments.py": ("search", "planner"),
    "planner/policy.py": ("search", "execution", "planner", "policy"),
    "planner/fine.py": ("search", "execution"),
}


def _run_time_default_reads(source, groups):
    """``DEFAULT.<group>`` attribute reads in ``source`` outside the default values of parameters."""
    import ast

    tree = ast.parse(source)
    in_defaults = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            for default in [*node.args.defaults, *(d for d in node.args.kw_defaults if d is not None)]:
                in_defaults.update(id(n) for n in ast.walk(default))
    return [
        f"{node.lineno}: DEFAULT.{node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and isinstance(node.value, ast.Name)
        and node.value.id == "DEFAULT"
        and node.attr in groups
        and id(node) not in in_defaults
    ]


def test_no_run_time_read_of_the_default_profile_on_the_solve_and_verify_path():
    from pathlib import Path

    root = Path(fixplan.__file__).parent
    found = {rel: _run_time_default_reads((root / rel).read_text(), groups) for rel, groups in RUN_TIME_GROUPS.items()}
    found = {rel: hits for rel, hits in found.items() if hits}
    assert not found, f"thresholds read from the default profile at run time (thread settings down): {found}"
    # the scan sees a read in a body, not one in a default value
    probe = (
        "def f(x=DEFAULT.search.limit_fraction, *, y=DEFAULT.execution):\n    return x * DEFAULT.search.binding_rel\n"
    )
    assert _run_time_default_reads(probe, ("search", "execution")) == ["2: DEFAULT.search"]
