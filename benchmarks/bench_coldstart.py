"""First run after installing: `fixplan solve` with an empty numba cache, after
`make install`'s precompile step, and warm.

numba keeps compiled kernels on disk (``cache=True``): by default in ``__pycache__`` next to each
module, or under ``NUMBA_CACHE_DIR``. Each measurement here points ``NUMBA_CACHE_DIR`` at a fresh
temporary directory, which is what a fresh clone's empty ``__pycache__`` is, without touching the
cache of the working tree:

1. cold: ``fixplan solve`` on the default fixture with the empty cache (what a fresh clone paid
   before ``make install`` compiled anything);
2. install: ``python -m fixplan.cli.precompile --no-aot`` into another empty cache (the step
   ``make install`` runs, without its ahead-of-time build, which writes into the package and does
   not serve the 3D default fixture);
3. first run after install: ``fixplan solve`` with that cache;
4. warm: the same command twice more.

Target: 3 within 2× of 4.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from run import Section


def _timed(cmd: list[str], cache: Path, cwd: Path) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, env=env, cwd=cwd)
    return time.perf_counter() - t0


def _size_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 1e6


def run(quick: bool) -> Section:
    exe = str(Path(sys.executable).with_name("fixplan"))
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        solve = [exe, "solve", "--out", str(tmp / "plan.json"), "--force"]
        cold = _timed(solve, tmp / "cache-cold", tmp)
        installed = tmp / "cache-installed"
        install = _timed([sys.executable, "-m", "fixplan.cli.precompile", "--quiet", "--no-aot"], installed, tmp)
        first = _timed(solve, installed, tmp)
        warm = [_timed(solve, installed, tmp) for _ in range(2 if quick else 3)]
        size = _size_mb(installed)
    warm_med = statistics.median(warm)
    ratio = first / warm_med
    rows = [
        {"case": "cold: empty cache", "wall_s": cold, "ratio_to_warm": cold / warm_med},
        {"case": "make install's precompile step", "wall_s": install, "ratio_to_warm": float("nan")},
        {"case": "first solve after install", "wall_s": first, "ratio_to_warm": ratio},
        *({"case": f"warm solve {i + 1}", "wall_s": w, "ratio_to_warm": w / warm_med} for i, w in enumerate(warm)),
    ]
    lines = [
        "`fixplan solve` on the default fixture, whole process, each cache state in a fresh `NUMBA_CACHE_DIR`",
        "(a fresh clone's empty `__pycache__`; `make install` fills the package's own `__pycache__` the same way).",
        "",
        "| run | wall [s] | × warm (median) |",
        "|---|---:|---:|",
    ]
    for r in rows:
        x = r["ratio_to_warm"]
        lines.append(f"| {r['case']} | {r['wall_s']:.2f} | {'–' if x != x else f'{x:.2f}'} |")
    lines += [
        "",
        f"The precompile step (`python -m fixplan.cli.precompile`, run by `make install`) wrote {size:.1f} MB of "
        "compiled kernels; it runs the commands themselves (solve, simulate 3D/2D, classify, map, the FCLib solvers) "
        "on small inputs, so the cache holds the signatures later runs look up.",
        "",
        f"Target: the first `fixplan solve` after install within 2× a warm run: **{first:.2f} s** vs "
        f"**{warm_med:.2f} s** warm ({ratio:.2f}×: {'met' if ratio <= 2.0 else 'missed'}); with an empty cache it "
        f"took {cold:.1f} s ({cold / warm_med:.0f}×).",
    ]
    return Section("First run after installing: numba's cache", "\n".join(lines), rows)
