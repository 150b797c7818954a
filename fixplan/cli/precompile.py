"""Fill numba's on-disk cache with every kernel the commands use: ``python -m fixplan.cli.precompile``.

fixplan's kernels are ``numba.njit(cache=True)``: compiled on first use (about a minute and a
half for ``fixplan solve`` on a fresh clone, several minutes on a loaded machine), then loaded
from the cache in a fraction of a second. ``make install`` runs this module once, so that the
first command a user runs after installing starts warm.

It runs the commands themselves, in this process and on small inputs: ``solve`` and
``classify`` on the bundled default fixture, ``simulate`` in 3D (compiled loop and per-step
stepping) and 2D, ``map`` and the FCLib solvers (``auto`` and each method) on small problems,
a mesh part's AABB tree and point queries, and a mesh part's engine step.
Running the real code paths compiles exactly the signatures (argument types and layouts) that
later runs look up; a hand-written list of signatures would drift from the code.

Then it compiles the kernels of the 2D solve path ahead of time (:func:`build_aot`, about
half a minute): ``fixplan/_aot<suffix>`` and ``fixplan/_aot.json``, loaded by :mod:`fixplan.aot`
without importing numba. ``--no-aot`` skips that.

Where the cache lives (numba's rules): ``NUMBA_CACHE_DIR`` when set, else ``__pycache__`` next
to each module (``fixplan/engine/__pycache__/*.nbi`` and ``*.nbc``), or a per-user directory
when the package directory is not writable. Run this module with the same setting as later
runs. An entry is invalidated when its source file changes (numba compares the file's
modification time and size), so after editing a kernel run it again (or let the next command
compile it).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fixplan import aot
from fixplan.files import write_output, write_text

RECT_2D = """format = 1
[scene]
name = "precompile-2d"
dimension = 2
gravity = [0.0, -9.81]
[workpiece]
shape = "rectangle"
size = [0.20, 0.10]
mass = 1.0
start = { position = [0.10, 0.05], angle_deg = 0.0 }
[[locator]]
name = "B1"
position = [0.05, 0.0]
friction = 0.5
face = "-y"
[[locator]]
name = "B2"
position = [0.15, 0.0]
friction = 0.5
face = "-y"
[[locator]]
name = "S1"
position = [0.0, 0.05]
friction = 0.5
face = "-x"
"""


def cache_location() -> str:
    """Where numba writes fixplan's kernels (``NUMBA_CACHE_DIR`` or the package's ``__pycache__``)."""
    custom = os.environ.get("NUMBA_CACHE_DIR", "")
    if custom:
        return f"NUMBA_CACHE_DIR={custom}"
    return str(Path(__file__).resolve().parent / "__pycache__") + " (and the other packages' __pycache__)"


def _cli(*args: str) -> None:
    """Run one fixplan command in this process, output discarded; a failure is raised."""
    from fixplan.cli import app

    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            app(list(args), standalone_mode=False)
        except SystemExit as exc:  # typer's exit on success is code 0 or None
            if exc.code not in (0, None):
                raise RuntimeError(f"fixplan {' '.join(args)} exited with {exc.code}") from exc


def _fclib_problems() -> None:
    """The FCLib solvers (auto and each method) on a small 3D and a small 2D problem."""
    import numpy as np
    import scipy.sparse as sp

    from fixplan.engine import SOLVERS, build_problem, solve
    from fixplan.settings import DEFAULT

    rng = np.random.default_rng(0)
    for dim in (3, 2):
        n_c = 4
        m = dim * n_c
        A = rng.normal(size=(m, 6))
        W = sp.csr_matrix(A @ A.T + 1e-3 * np.eye(m))
        q = rng.normal(size=m)
        problem = build_problem(W, q, 0.3, dims=dim)
        for name in sorted(SOLVERS):
            solve(problem, name, tol=DEFAULT.engine.fclib_tolerance, max_iter=50)


def _simulator_paths() -> None:
    """Simulator.step (the haptic loop's per-tick call) and a scheduled-wrench run, 3D and 2D."""
    import numpy as np

    import fixplan
    from fixplan.engine.simulator import Simulator, WrenchSchedule

    for fx in (fixplan.load(fixplan.default_fixture_path()), fixplan.loads(RECT_2D)):
        n = 6 if fx.dimension == 3 else 3
        sim = Simulator(fx)
        for _ in range(3):
            sim.step(np.zeros(n))
        sim.run(0.003, WrenchSchedule(np.array([0.0, 0.001]), np.zeros((2, n))), record_every=2)


def _mesh_queries() -> None:
    """A mesh part's AABB tree and point queries (one contact, and two in the L's concave corner)."""
    import numpy as np

    from fixplan.geometry.cells import cell_surface, l_bracket_cells
    from fixplan.geometry.mesh import Mesh

    mesh = Mesh(*cell_surface(*l_bracket_cells(0.1, 0.04, 0.06, 0.01)))
    mesh.project(np.array([0.05, 0.02, 0.03]))
    mesh.contacts(np.array([0.013, 0.02, 0.013]))


def _mesh_simulation(tmp: Path) -> None:
    """Simulator.step of a mesh part (one compiled call a step: its detection too), with a floor."""
    import numpy as np

    import fixplan
    from fixplan.engine.simulator import Simulator
    from fixplan.geometry.cells import box_cells, cell_surface
    from fixplan.geometry.mesh import stl_bytes

    stl = stl_bytes(*cell_surface(*box_cells((0.2, 0.1, 0.05), 2)))
    write_output(tmp / "box.stl", lambda path: path.write_bytes(stl))
    text = (
        'format = 1\n[scene]\nname = "precompile-mesh"\ndimension = 3\n'
        '[workpiece]\nshape = "mesh"\nfile = "box.stl"\nmass = 2.0\nstart = { position = [0.0, 0.0, 0.0] }\n'
        '[[locator]]\nname = "B1"\nposition = [0.0, 0.0, -0.028]\nradius = 0.003\nfriction = 0.3\n'
        '[[obstacle]]\nname = "floor"\nshape = "plane"\npoint = [0.0, 0.0, -0.025]\nnormal = [0.0, 0.0, 1.0]\n'
    )
    write_text(tmp / "mesh.toml", text)
    sim = Simulator(fixplan.load(tmp / "mesh.toml"))
    for _ in range(3):
        sim.step(np.zeros(6))


def _pin_simulation(tmp: Path) -> None:
    """Simulator.step of the library's housing on two pins, as a box and as a mesh part (the pin kernels: contacts and slots).

    Skipped outside a checkout (an installed wheel has no ``problems/``): the kernels then compile
    on their first use.
    """
    import numpy as np

    import fixplan
    from fixplan.engine.simulator import Simulator
    from fixplan.geometry.cells import box_cells, cell_surface
    from fixplan.geometry.mesh import stl_bytes

    path = Path(fixplan.__file__).resolve().parents[1] / "problems" / "housing-2-pins.toml"
    if not path.is_file():
        return
    stl = stl_bytes(*cell_surface(*box_cells((120.0, 80.0, 30.0), 1)))
    write_output(tmp / "housing.stl", lambda out: out.write_bytes(stl))
    box = 'shape = "box"\nsize = [0.12, 0.08, 0.03]'
    text = path.read_text(encoding="utf-8")
    write_text(tmp / "housing-mesh.toml", text.replace(box, 'shape = "mesh"\nfile = "housing.stl"\nunits = "mm"'))
    for fixture in (fixplan.load(path), fixplan.load(tmp / "housing-mesh.toml")):
        sim = Simulator(fixture)
        for _ in range(3):
            sim.step(np.zeros(6))


def steps(tmp: Path) -> list[tuple[str, Callable[[], None]]]:
    """The workloads, in order: (label, function)."""
    from fixplan import default_fixture_path

    data = default_fixture_path().parent
    rect = tmp / "rect.toml"
    write_text(rect, RECT_2D)
    w3 = ",".join(["-2.5"] * 3 + ["0"] * 3)
    return [
        ("solve (default fixture)", lambda: _cli("solve", "--out", str(tmp / "plan.json"), "--force")),
        ("solve (a 2D plate)", lambda: _cli("solve", str(rect), "--out", str(tmp / "plan2.json"), "--force")),
        ("simulate 3D", lambda: _cli("simulate", "--pose", "goal", "--wrench", w3, "--duration", "0.01")),
        ("simulate 2D", lambda: _cli("simulate", str(rect), "--duration", "0.01")),
        ("simulator step and schedules", _simulator_paths),
        ("classify", lambda: _cli("classify", "--wrenches", str(data / "demo_wrenches.csv"), "--json")),
        (
            "map",
            lambda: _cli(
                "map", "--axes", "Fx,Tz", "--range", "-10:10,-1:1", "--n", "4", "--out", str(tmp / "m.png"), "--force"
            ),
        ),
        ("FCLib solvers", _fclib_problems),
        ("mesh queries", _mesh_queries),
        ("mesh part in the engine", lambda: _mesh_simulation(tmp)),
        ("pins in the engine", lambda: _pin_simulation(tmp)),
    ]


def _argument(numba_type: Any) -> dict[str, Any]:
    """One argument type of a compiled signature as :mod:`fixplan.aot`'s manifest records it."""
    from numba.core import types

    if isinstance(numba_type, types.Array) and numba_type.aligned and numba_type.layout in ("C", "A"):
        dtype = str(numba_type.dtype)
        if dtype in ("float64", "int64", "bool"):
            return {
                "kind": "array",
                "dtype": dtype,
                "ndim": numba_type.ndim,
                "contiguous": numba_type.layout == "C",
                "mutable": bool(numba_type.mutable),
            }
    elif numba_type in (types.float64, types.int64, types.boolean):
        return {"kind": "scalar", "dtype": str(numba_type)}
    raise TypeError(f"no ahead-of-time export for an argument of type {numba_type}")


def build_aot(out_dir: Path | None = None) -> str:
    """Compile :data:`fixplan.aot.EXPORTS` with ``numba.pycc`` into ``fixplan/_aot*`` and its manifest.

    Every signature the JIT dispatchers hold (the workloads just compiled or loaded them) becomes
    one variant; a signature with an argument type the guard cannot check is left to the JIT.
    Built in a temporary directory and moved into place, so a running process never sees half a
    build. Returns a one-line summary.
    """
    import importlib
    import shutil
    import warnings

    import numba
    from numba.pycc import CC

    out_dir = out_dir or aot.PACKAGE_DIR
    hexdigest = aot.fingerprint()
    manifest: dict[str, Any] = {"fingerprint": hexdigest, "numba": numba.__version__, "exports": {}}
    skipped: list[str] = []
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba.pycc's pending-deprecation notice
        cc = CC(aot.EXTENSION)
        cc.output_dir = tmp
        cc.target_cpu = "host"  # as the JIT compiles
        for module, name in aot.EXPORTS:
            dispatcher = getattr(importlib.import_module(module), name)
            entries: list[dict[str, Any]] = []
            for argtypes in dispatcher.signatures:
                try:
                    args = [_argument(t) for t in argtypes]
                except TypeError as exc:
                    skipped.append(f"{module}.{name}{tuple(str(t) for t in argtypes)}: {exc}")
                    continue
                export = aot.export_name(module, name, len(entries))
                cc.export(export, dispatcher.overloads[argtypes].signature)(dispatcher.py_func)
                entries.append({"export": export, "args": args})
            if entries:
                manifest["exports"][f"{module}.{name}"] = entries
            else:
                skipped.append(f"{module}.{name}: no compiled signature to export (no workload called it)")
        namespace = {"FINGERPRINT": aot.fingerprint_int(hexdigest)}
        exec("def fingerprint__():\n    return FINGERPRINT\n", namespace)  # noqa: S102 - a constant function
        cc.export("fingerprint__", "i8()")(namespace["fingerprint__"])
        cc.compile()
        (built,) = Path(tmp).glob(f"{aot.EXTENSION}.*")
        target = out_dir / built.name
        for old in out_dir.glob(f"{aot.EXTENSION}.*"):
            if old.suffix != ".json" and old.name != built.name:
                old.unlink()  # an extension of another Python version or platform
        # each renamed into place (files.write_output): a failed build never leaves half an extension
        write_output(target, lambda path: shutil.move(str(built), path))
        write_text(out_dir / aot.MANIFEST.name, json.dumps(manifest, indent=1) + "\n")
    n = sum(len(v) for v in manifest["exports"].values())
    text = f"ahead-of-time kernels: {n} exports in {target.name}"
    return text + (f"; left to the JIT: {'; '.join(skipped)}" if skipped else "")


def main(argv: list[str] | None = None) -> int:
    """Run every workload, then build the ahead-of-time kernels; exit status 1 when a step failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quiet", action="store_true", help="print only the total")
    parser.add_argument("--no-aot", action="store_true", help="only fill numba's cache; build no extension")
    args = parser.parse_args(argv)
    # The workloads must run numba's dispatchers (not a previous build's extension), so that their
    # signatures are there to export.
    os.environ[aot.ENV] = "jit"
    t_all = time.perf_counter()
    print(f"fixplan precompile: numba cache in {cache_location()}", file=sys.stderr, flush=True)
    failed = 0
    with tempfile.TemporaryDirectory() as tmp:
        for label, fn in steps(Path(tmp)):
            t0 = time.perf_counter()
            try:
                fn()
            except Exception as exc:  # noqa: BLE001 - one failing workload must not stop the others
                failed += 1
                print(f"  {label}: failed ({type(exc).__name__}: {exc})", file=sys.stderr, flush=True)
                continue
            if not args.quiet:
                print(f"  {label}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    if not args.no_aot:
        t0 = time.perf_counter()
        try:
            summary = build_aot()
        except Exception as exc:  # noqa: BLE001 - the JIT still works without the extension
            failed += 1
            print(f"  ahead-of-time build: failed ({type(exc).__name__}: {exc})", file=sys.stderr, flush=True)
        else:
            print(f"  {summary}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    print(
        f"fixplan precompile: {time.perf_counter() - t_all:.1f} s" + (f", {failed} steps failed" if failed else ""),
        file=sys.stderr,
    )
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
