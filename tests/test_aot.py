"""The ahead-of-time kernels (:mod:`fixplan.aot`) compute what numba's JIT computes, to the bit.

The extension is built by ``python -m fixplan.cli.precompile`` (``make install`` runs it). The
tests that need it skip, with the reason :func:`fixplan.aot.status` gives, when it is not built
from this very source (after editing a file, until the next precompile). The guard and the
fallback rules are tested without it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS, ROOT

import fixplan
from fixplan import aot
from fixplan.engine import simulator as simulator_module
from fixplan.engine.simulator import Simulator, WrenchSchedule

BUILT = aot.status().startswith("ahead-of-time")
needs_build = pytest.mark.skipif(not BUILT, reason=f"no usable extension: {aot.status()}")

PLATES_2D = ["gen-plate-2d-s2026-000.toml", "gen-plate-2d-s2026-002.toml", "polygon-2d.toml", "naive-order-jams.toml"]


@pytest.fixture(autouse=True)
def _fresh_fallbacks(monkeypatch) -> None:
    """Each test counts its own fallbacks (a test elsewhere may call a kernel with other types on purpose)."""
    monkeypatch.setattr(aot, "fallbacks", {})


def _jit(module: str, name: str):  # numba's dispatcher itself
    import importlib

    return getattr(importlib.import_module(module), name)


# -- the guard: a compiled function is only called with the types it was built for ----------
def _spec(**kw):
    return aot._spec(kw)


def _generated(args, specs) -> bool:  # the per-variant checker the kernels call
    return aot._checker(specs)(args)


@pytest.mark.parametrize("accepts", [aot._accepts, _generated], ids=["loop", "generated"])
def test_the_guard_accepts_exact_types_only(accepts) -> None:
    specs = (
        _spec(kind="scalar", dtype="float64"),
        _spec(kind="scalar", dtype="int64"),
        _spec(kind="array", dtype="float64", ndim=2, contiguous=True, mutable=True),
    )
    A = np.zeros((3, 2))
    assert accepts((1.5, 3, A), specs)
    assert accepts((np.float64(1.5), np.int64(3), A), specs)
    assert not accepts((1, 3, A), specs)  # an int where a float64 is compiled: numba would type it int64
    assert not accepts((1.5, True, A), specs)  # a bool is not an int64
    assert not accepts((1.5, 3.0, A), specs)
    assert not accepts((1.5, 3, A.astype(np.float32)), specs)  # would be reinterpreted
    assert not accepts((1.5, 3, A.astype(np.int64)), specs)
    assert not accepts((1.5, 3, np.zeros(3)), specs)  # rank
    assert not accepts((1.5, 3, np.asfortranarray(np.zeros((3, 2)))), specs)  # not C-contiguous
    assert not accepts((1.5, 3, np.zeros((3, 4))[:, ::2]), specs)
    assert not accepts((1.5, 3, A.tolist()), specs)  # a list would crash the process
    readonly = A.copy()
    readonly.flags.writeable = False
    assert not accepts((1.5, 3, readonly), specs)
    assert not accepts((1.5, 3), specs)
    assert not accepts((1.5, 3, A, A), specs)
    # arrays checked only for what they were built for (rank and dtype always)
    loose = (_spec(kind="array", dtype="float64", ndim=1, contiguous=False, mutable=False),)
    strided = np.zeros(6)[::2]
    strided.flags.writeable = False
    assert accepts((strided,), loose)
    assert not accepts((strided.astype(np.float32),), loose)
    assert accepts((), ())
    assert not accepts((1.5,), ())


def test_a_call_no_variant_accepts_goes_to_the_jit_and_is_counted(monkeypatch) -> None:
    calls: list[str] = []
    jit = aot._JitKernel("m", "f")
    jit._function = lambda *a: calls.append("jit") or "jit"  # type: ignore[assignment]
    spec = (_spec(kind="array", dtype="float64", ndim=1, contiguous=True, mutable=True),)
    kernel = aot._AotKernel("m.f", [(spec, lambda *a: calls.append("aot") or "aot")], jit)
    monkeypatch.setattr(aot, "fallbacks", {})
    assert kernel(np.zeros(2)) == "aot"
    assert kernel(np.zeros(2, dtype=np.float32)) == "jit"
    assert kernel([0.0, 0.0]) == "jit"
    assert calls == ["aot", "jit", "jit"] and aot.fallbacks == {"m.f": 2}


def test_a_fixed_argument_is_checked_by_identity_and_in_full_when_replaced(monkeypatch) -> None:
    """``fixing``: the fixed array's type is checked once; a call with that very object skips its check, one
    with another object is checked in full (a good one still runs compiled), a bad one goes to the JIT."""
    calls: list[str] = []
    jit = aot._JitKernel("m", "f")
    jit._function = lambda *a: calls.append("jit") or "jit"  # type: ignore[assignment]
    spec = (_spec(kind="array", dtype="float64", ndim=1, contiguous=True, mutable=True),) * 2
    kernel = aot._AotKernel("m.f", [(spec, lambda *a: calls.append("aot") or "aot")], jit)
    monkeypatch.setattr(aot, "fallbacks", {})
    fixed = np.zeros(3)
    bound = kernel.fixing({0: fixed})
    assert bound(fixed, np.zeros(2)) == "aot"
    assert bound(np.zeros(3), np.zeros(2)) == "aot"  # another object, checked in full
    assert bound(np.zeros(3, dtype=np.float32), np.zeros(2)) == "jit"
    assert bound(fixed, [0.0]) == "jit"  # the other arguments are still checked
    assert calls == ["aot", "aot", "jit", "jit"] and aot.fallbacks == {"m.f": 2}
    # a fixed value no variant accepts binds nothing: every call is checked in full
    assert kernel.fixing({0: np.zeros(3, dtype=np.int64)})(fixed, np.zeros(2)) == "aot"
    assert aot._JitKernel("m", "f").fixing({0: fixed}) is not None


def test_without_a_usable_build_every_kernel_is_numbas_dispatcher(monkeypatch, tmp_path: Path) -> None:
    """Not built, built from other source, or FIXPLAN_KERNELS=jit: the JIT, and status says why."""
    cases = [
        ({"MANIFEST": tmp_path / "none.json"}, {}, "not built"),
        ({"fingerprint": lambda: "0" * 64}, {}, "the source changed"),
        ({}, {aot.ENV: "jit"}, f"{aot.ENV}=jit"),
    ]
    manifest = tmp_path / "_aot.json"
    manifest.write_text(json.dumps({"fingerprint": aot.fingerprint(), "exports": {}}))
    for attrs, env, reason in cases:
        with monkeypatch.context() as m:
            m.setattr(aot, "MANIFEST", manifest)
            for k, v in attrs.items():
                m.setattr(aot, k, v)
            for k, v in env.items():
                m.setenv(k, v)
            aot._load.cache_clear()
            aot.kernel.cache_clear()
            assert reason in aot.status()
            assert isinstance(aot.kernel("fixplan.engine.step", "step2"), aot._JitKernel)
    aot._load.cache_clear()
    aot.kernel.cache_clear()


def test_the_fingerprint_changes_with_any_source_byte(monkeypatch, tmp_path: Path) -> None:
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    monkeypatch.setattr(aot, "PACKAGE_DIR", tmp_path)
    first = aot.fingerprint()
    assert aot.fingerprint() == first
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")
    assert aot.fingerprint() != first
    assert 0 <= aot.fingerprint_int(first) < 2**63


# -- the build: every export equals its JIT twin ----------------------------------------------
@needs_build
def test_the_manifest_covers_every_export_with_compiled_variants() -> None:
    exports = json.loads(aot.MANIFEST.read_text())["exports"]
    assert sorted(exports) == sorted(f"{m}.{n}" for m, n in aot.EXPORTS)
    for module, name in aot.EXPORTS:
        assert isinstance(aot.kernel(module, name), aot._AotKernel)


@needs_build
def test_nnls_equals_the_jit_bit_for_bit(rng: np.random.Generator) -> None:
    aot_nnls = aot.kernel("fixplan.jamming._classify_kernels", "nnls")
    jit_nnls = _jit("fixplan.jamming._classify_kernels", "nnls")
    for _ in range(200):
        m, n = rng.integers(2, 9), rng.integers(1, 12)
        A = np.ascontiguousarray(rng.normal(size=(m, n)))
        b = rng.normal(size=m) * 10.0 ** rng.integers(-3, 3)
        x_a, res_a, ok_a = aot_nnls(A, b, 50 * n + 50, 1e-12)
        x_j, res_j, ok_j = jit_nnls(A, b, 50 * n + 50, 1e-12)
        assert np.array_equal(x_a, x_j) and res_a == res_j and ok_a == ok_j
        assert np.all(x_a >= 0.0)
    assert aot.fallbacks.get("fixplan.jamming._classify_kernels.nnls", 0) == 0


@needs_build
def test_the_mesh_tree_and_queries_equal_the_jit_bit_for_bit(rng: np.random.Generator) -> None:
    from fixplan.geometry import Mesh
    from fixplan.geometry.cells import cell_surface, l_bracket_cells

    mesh = Mesh(*cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01)))
    arrays = mesh._kernel_arrays  # built by the compiled build_tree
    tri = arrays[0]
    m = tri.shape[0]
    trees = []
    for build in (
        aot.kernel("fixplan.geometry._mesh_kernels", "build_tree"),
        _jit("fixplan.geometry._mesh_kernels", "build_tree"),
    ):
        boxes, nodes, order = np.empty((2 * m, 6)), np.empty((2 * m, 4), dtype=np.int64), np.empty(m, dtype=np.int64)
        count = build(np.array(tri), mesh.settings.tree_leaf_triangles, boxes, nodes, order)
        trees.append((boxes[:count], nodes[:count], order))
    assert all(np.array_equal(a, b) for a, b in zip(*trees, strict=True))
    aot_query = aot.kernel("fixplan.geometry._mesh_kernels", "contacts")
    jit_query = _jit("fixplan.geometry._mesh_kernels", "contacts")
    for p in rng.uniform(-0.01, 0.11, size=(200, 3)):
        outs = [np.zeros((8, 7)), np.zeros((8, 7))]
        counts = [
            q(*map(float, p), 1e-6, mesh._same_m, *arrays, out)
            for q, out in zip((aot_query, jit_query), outs, strict=True)
        ]
        assert counts[0] == counts[1] and np.array_equal(outs[0], outs[1])
    assert not any(key.startswith("fixplan.geometry._mesh_kernels") for key in aot.fallbacks)


@needs_build
def test_the_witness_system_equals_the_jit_bit_for_bit(rng: np.random.Generator) -> None:
    from fixplan.jamming.sliding import Rows
    from fixplan.locating import contact_set

    aot_system = aot.kernel("fixplan.jamming._witness_kernels", "system")
    jit_system = _jit("fixplan.jamming._witness_kernels", "system")
    for name in PLATES_2D:
        fx = fixplan.load(PROBLEMS / name)
        cs = contact_set(fx, fx.goal_pose, [loc.name for loc in fx.locators])
        rows = Rows(cs)
        k = len(cs)
        for _ in range(20):
            roles = rng.integers(0, 3, size=k).astype(np.int64)
            # unknowns: a, then f_n of a sliding contact, λ (its size) of a sticking one, none if open
            nz = cs.ndof + int(np.sum(np.where(roles == 0, 1, np.where(roles == 1, rows.size, 0))))
            args = (
                rows.M,
                rows.Jall,
                rows.off,
                rows.size,
                rows.mu_arr,
                rows.Dm,
                rng.normal(size=cs.ndof),
                rng.normal(size=nz),
                roles,
            )
            for got, want in zip(aot_system(*args), jit_system(*args), strict=True):
                assert np.array_equal(got, want)


@needs_build
def test_the_witness_newton_and_fixed_point_equal_the_jit_bit_for_bit(rng: np.random.Generator) -> None:
    """The 3D classifier's two starts of the sliding witness (Newton, fixed point), AOT vs JIT."""
    from fixplan.jamming.sliding import Rows
    from fixplan.locating import contact_set

    K = "fixplan.jamming._witness_kernels"
    aot_newton, jit_newton = aot.kernel(K, "newton"), _jit(K, "newton")
    aot_fixed, jit_fixed = aot.kernel(K, "fixed_point"), _jit(K, "fixed_point")
    assert isinstance(aot_newton, aot._AotKernel) and isinstance(aot_fixed, aot._AotKernel)
    for name in ("box-3-2-1.toml", "gen-box-321-s2026-000.toml", *PLATES_2D[:2]):
        fx = fixplan.load(PROBLEMS / name)
        cs = contact_set(fx, fx.goal_pose, [loc.name for loc in fx.locators])
        rows = Rows(cs)
        k = len(cs)
        for _ in range(10):
            w = rng.normal(size=cs.ndof)
            fixed_args = (rows.M, rows.Jall, rows.off, rows.size, rows.mu_arr, rows.Dm, w)
            z0 = rng.normal(size=cs.ndof + k)
            assert np.array_equal(aot_fixed(*fixed_args, z0, 5), jit_fixed(*fixed_args, z0, 5))
            roles = rng.integers(0, 3, size=k).astype(np.int64)
            nz = cs.ndof + int(np.sum(np.where(roles == 0, 1, np.where(roles == 1, rows.size, 0))))
            z = rng.normal(size=nz)
            assert np.array_equal(aot_newton(*fixed_args, z, roles, 20), jit_newton(*fixed_args, z, roles, 20))
    assert not any(key.startswith(K) for key in aot.fallbacks)


@needs_build
@pytest.mark.parametrize("name", PLATES_2D)
def test_a_2d_simulation_steps_and_runs_identically(monkeypatch, name: str) -> None:
    """Simulator.step (the haptic loop's call) and Simulator.run (the compiled loop), AOT vs JIT."""
    fx = fixplan.load(PROBLEMS / name)
    pushes = np.array([[-2.0, -3.0, 0.05], [1.0, -4.0, -0.1], [0.0, 0.0, 0.0]])
    schedule = WrenchSchedule(np.array([0.0, 0.05, 0.1]), pushes)

    def simulate() -> tuple[list[np.ndarray], dict[str, np.ndarray]]:
        sim = Simulator(fx)
        states = []
        for t in range(150):
            info = sim.step(pushes[t // 50])
            states.append(np.concatenate([sim.pose.p_world, [sim.pose.angle_rad], sim.twist, [info.error]]))
        run = Simulator(fx).run(0.2, schedule, record_every=5)
        return states, run.arrays()

    states_aot, run_aot = simulate()
    assert isinstance(simulator_module._step2, aot._AotKernel)
    monkeypatch.setattr(simulator_module, "_step2", _jit("fixplan.engine.step", "step2"))
    monkeypatch.setattr(simulator_module, "_run2", _jit("fixplan.engine.step", "run2"))
    states_jit, run_jit = simulate()
    assert all(np.array_equal(a, b) for a, b in zip(states_aot, states_jit, strict=True))
    assert run_aot.keys() == run_jit.keys()
    assert all(np.array_equal(run_aot[k], run_jit[k], equal_nan=True) for k in run_aot)
    assert not any(key.startswith("fixplan.engine.step") for key in aot.fallbacks)


def _states(fx: fixplan.Fixture, push: np.ndarray) -> list[np.ndarray]:
    """100 Simulator steps under ``push``: pose, rotation, twist and residual after each."""
    sim = Simulator(fx)
    out = []
    for _ in range(100):
        info = sim.step(push)
        out.append(np.concatenate([sim.pose.p_world, sim.pose.R_world_body.ravel(), sim.twist, [info.error]]))
    return out


def _mesh_step_aot_equals_jit(fx, push, monkeypatch) -> None:
    """The mesh step's states under ``push``: the ahead-of-time kernel's equal the JIT's, with no fallback."""
    from fixplan.engine import mesh_slots as mesh_slots_module

    states_aot = _states(fx, push)
    assert isinstance(mesh_slots_module._mesh_step3, aot._AotKernel)
    monkeypatch.setattr(mesh_slots_module, "_mesh_step3", _jit("fixplan.engine._mesh_slot_kernels", "mesh_step3"))
    states_jit = _states(fx, push)
    assert all(np.array_equal(a, b) for a, b in zip(states_aot, states_jit, strict=True))
    assert not any(key.startswith("fixplan.engine._mesh_slot_kernels") for key in aot.fallbacks)


@needs_build
def test_a_mesh_part_steps_identically(monkeypatch) -> None:
    """Simulator.step of a mesh part (detection, slots and step in one kernel), AOT vs JIT."""
    fx = fixplan.load(PROBLEMS / "meshes" / "l-bracket.toml")
    push = np.array([-1.0, 0.5, -2.0, 0.01, 0.0, 0.02])
    _mesh_step_aot_equals_jit(fx, push, monkeypatch)


@needs_build
def test_a_mesh_part_on_pins_steps_identically(monkeypatch, tmp_path) -> None:
    """Simulator.step of the housing as a mesh part on its two pins (the pins' closed forms in the mesh step), AOT vs JIT."""
    from fixplan.geometry.cells import box_cells, cell_surface
    from fixplan.geometry.mesh import stl_bytes

    (tmp_path / "housing.stl").write_bytes(stl_bytes(*cell_surface(*box_cells((120.0, 80.0, 30.0), 2))))
    text = (PROBLEMS / "housing-2-pins.toml").read_text(encoding="utf-8")
    box = 'shape = "box"\nsize = [0.12, 0.08, 0.03]'
    assert box in text
    (tmp_path / "mesh.toml").write_text(text.replace(box, 'shape = "mesh"\nfile = "housing.stl"\nunits = "mm"'))
    fx = fixplan.load(tmp_path / "mesh.toml")
    push = np.array([0.5, -0.3, -5.0, 0.01, -0.02, 0.0])
    _mesh_step_aot_equals_jit(fx, push, monkeypatch)


@needs_build
def test_a_part_on_pins_steps_identically(monkeypatch) -> None:
    """Simulator.step of the housing on two pins (the pins' contacts and slots), AOT vs JIT."""
    from fixplan.engine import pin_slots as pin_slots_module

    fx = fixplan.load(PROBLEMS / "housing-2-pins.toml")
    push = np.array([0.5, -0.3, -5.0, 0.01, -0.02, 0.0])
    states_aot = _states(fx, push)
    assert isinstance(pin_slots_module._pose_contacts, aot._AotKernel)
    assert isinstance(pin_slots_module._pin_slots, aot._AotKernel)
    monkeypatch.setattr(pin_slots_module, "_pose_contacts", _jit("fixplan.geometry._pin_kernels", "pose_contacts"))
    monkeypatch.setattr(pin_slots_module, "_pin_slots", _jit("fixplan.engine._pin_slot_kernels", "pin_slots"))
    states_jit = _states(fx, push)
    assert all(np.array_equal(a, b) for a, b in zip(states_aot, states_jit, strict=True))
    assert not any("_pin" in key for key in aot.fallbacks)


def _solve_json(path: Path, env: dict[str, str]) -> tuple[dict, list[str]]:
    code = (
        "import json, sys; from fixplan.cli import main; from fixplan import aot\n"
        "try:\n    main(['solve', sys.argv[1], '--json'])\nexcept SystemExit:\n    pass\n"
        "print(json.dumps({'numba': 'numba' in sys.modules, 'fallbacks': aot.fallbacks,\n"
        "  'scipy.linalg': 'scipy.linalg' in sys.modules,\n"
        "  'lapack': 'scipy.linalg.cython_lapack' in sys.modules}), file=sys.stderr)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, str(path)], capture_output=True, text=True, cwd=ROOT, env=env, timeout=600
    )
    return json.loads(proc.stdout), proc.stderr.strip().splitlines()


def _without_wall_clock(value):
    """The answer without the fields measured on the wall clock: benchmarks/behaviour.py's one rule."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("behaviour", ROOT / "benchmarks" / "behaviour.py")
    assert spec is not None and spec.loader is not None
    behaviour = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(behaviour)
    return behaviour.without_wall_clock(value)


@needs_build
@pytest.mark.parametrize("name", ["gen-plate-2d-s2026-000.toml", "gen-box-321-s2026-000.toml"])
def test_a_solve_runs_without_numba_and_answers_as_the_jit_does(name: str) -> None:
    """2D and 3D: planning, the policy and the haptic verification (spatial step and coupling)."""
    import os

    path = PROBLEMS / name
    env = {k: v for k, v in os.environ.items() if k != aot.ENV}
    out_aot, err_aot = _solve_json(path, env)
    out_jit, err_jit = _solve_json(path, {**env, aot.ENV: "jit"})
    # LAPACK reached without scipy.linalg's package init (0.18 s), the answers the JIT's (which imports it)
    seen = json.loads(err_aot[-1])
    assert seen == {"numba": False, "fallbacks": {}, "scipy.linalg": False, "lapack": seen["lapack"]}
    if "box" in name:
        assert seen["lapack"] is True  # the 3D witness kernels called LAPACK
    assert json.loads(err_jit[-1])["numba"] is True
    assert out_aot["status"] == "planned"
    assert _without_wall_clock(out_aot) == _without_wall_clock(out_jit)


def test_lapack_preloaded_without_the_package_init_leaves_scipy_linalg_whole() -> None:
    """The preloaded Cython LAPACK is the one a later ``import scipy.linalg`` uses, and that import works."""
    code = (
        "import json, sys; from fixplan import aot; aot._preload_lapack()\n"
        "before = ['scipy.linalg' in sys.modules, 'scipy.linalg.cython_lapack' in sys.modules]\n"
        "lap = sys.modules.get('scipy.linalg.cython_lapack')\n"
        "import numpy as np, scipy.linalg, scipy.linalg.cython_lapack as again\n"
        "a = np.array([[4.0, 1.0], [2.0, 3.0]]); x = scipy.linalg.solve(a, np.array([1.0, 2.0]))\n"
        "print(json.dumps([before, again is lap, float(abs(a @ x - [1.0, 2.0]).max())]))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    before, same, residual = json.loads(proc.stdout)
    assert before == [False, True]
    assert same is True
    assert residual < 1e-14
