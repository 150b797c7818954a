"""Fill numba's on-disk cache with every kernel the commands use: ``python -m fixplan.cli.precompile``.

fixplan's kernels are ``numba.njit(cache=True)``: compiled on first use (about a minute and a
half for ``fixplan solve`` on a fresh clone, several minutes on a loaded machine), then loaded
from the cache in a fraction of a second. ``make install`` runs this module once, so that the
first command a user runs after installing starts warm.

It runs the commands themselves, in this process and on small inputs: ``solve`` and
``classify`` on the bundled default fixture, ``simulate`` in 3D (compiled loop and per-step
stepping) and 2D, ``map`` and the FCLib solvers (``auto`` and each method) on small problems.
Running the real code paths compiles exactly the signatures (argument types and layouts) that
later runs look up; a hand-written list of signatures would drift from the code.

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
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

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


def steps(tmp: Path) -> list[tuple[str, Callable[[], None]]]:
    """The workloads, in order: (label, function)."""
    from fixplan import default_fixture_path

    data = default_fixture_path().parent
    rect = tmp / "rect.toml"
    rect.write_text(RECT_2D)
    w3 = ",".join(["-2.5"] * 3 + ["0"] * 3)
    return [
        ("solve (default fixture)", lambda: _cli("solve", "--out", str(tmp / "plan.json"), "--force")),
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
    ]


def main(argv: list[str] | None = None) -> int:
    """Run every workload; exit status 1 when one failed (the others still ran)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quiet", action="store_true", help="print only the total")
    args = parser.parse_args(argv)
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
    print(
        f"fixplan precompile: {time.perf_counter() - t_all:.1f} s" + (f", {failed} workloads failed" if failed else ""),
        file=sys.stderr,
    )
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
