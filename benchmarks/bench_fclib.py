"""FCLib problems: error reached against time, per problem, solver and tolerance.

Reads every ``*.hdf5`` in ``../shared/data/fclib`` (beside the checkout) and solves each with
every registered solver but the slow NumPy reference, at tolerances 1e-4, 1e-6, 1e-8 and 1e-10
(each solve from a cold start). Numba kernels are compiled before timing. The time is the best
of ``reps`` runs (1 with ``--quick``, 3 otherwise); reading and condensing the file is excluded.

Without ``--quick`` it also times the solvers on box stacks where NSGS stalls (redundant corner
contacts, mass ratio 10 between boxes), the evidence behind the robust solver's choice.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from run import Section

from fixplan.engine import build_problem, get_solver, read_fclib

HERE = Path(__file__).resolve().parent
FCLIB_DIR = HERE.parent.parent / "shared" / "data" / "fclib"
SOLVERS = ("nsgs", "socp", "auto")
TOLERANCES = (1e-4, 1e-6, 1e-8, 1e-10)
MAX_ITER = {"nsgs": 100_000, "socp": 60, "auto": 60}
SHIFT_S = 1e-3  # shift of the geometric mean of times [s]


def shifted_geometric_mean(values: list[float], shift: float = SHIFT_S) -> float:
    """``exp(mean(log(v + shift))) − shift`` (qpbenchmark's summary of times)."""
    if not values:
        return math.nan
    return float(np.exp(np.mean(np.log(np.asarray(values) + shift))) - shift)


def box_stack(n_boxes: int, mass_ratio: float, mu: float, seed: int):
    """Stack of unit boxes, 4 corner contacts per interface (rank-deficient W)."""
    rng = np.random.default_rng(seed)
    side, height, h = 1.0, 0.5, 1e-3
    nd = 6 * n_boxes
    Minv = np.zeros((nd, nd))
    f, v0 = np.zeros(nd), np.zeros(nd)
    for k in range(n_boxes):
        m = mass_ratio**k
        inertia = m / 12 * np.array([side**2 + height**2, side**2 + height**2, 2 * side**2])
        Minv[6 * k : 6 * k + 3, 6 * k : 6 * k + 3] = np.eye(3) / m
        Minv[6 * k + 3 : 6 * k + 6, 6 * k + 3 : 6 * k + 6] = np.diag(1 / inertia)
        f[6 * k + 2] = -9.81 * m
        v0[6 * k : 6 * k + 2] = 0.01 * rng.standard_normal(2)
        v0[6 * k + 2] = -0.01 * abs(rng.standard_normal())
    rows = []
    frame = (np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))
    for k in range(n_boxes):
        for sx in (-1, 1):
            for sy in (-1, 1):
                p = np.array([sx * side / 2, sy * side / 2, k * height])
                for d in frame:
                    row = np.zeros(nd)
                    row[6 * k : 6 * k + 3] = d
                    row[6 * k + 3 : 6 * k + 6] = np.cross(p - [0, 0, (k + 0.5) * height], d)
                    if k > 0:
                        row[6 * (k - 1) : 6 * k - 3] -= d
                        row[6 * k - 3 : 6 * k] -= np.cross(p - [0, 0, (k - 0.5) * height], d)
                    rows.append(row)
    J = np.array(rows)
    return build_problem(J @ Minv @ J.T, J @ (v0 + h * Minv @ f), mu, dims=3)


def _time_solve(problem, solver: str, tol: float, reps: int) -> dict:
    solve = get_solver(solver)
    best = None
    for _ in range(reps):
        t0 = time.perf_counter()
        sol = solve(problem, tol=tol, max_iter=MAX_ITER[solver])
        elapsed = time.perf_counter() - t0
        if best is None or elapsed < best[0]:
            best = (elapsed, sol)
    assert best is not None
    elapsed, sol = best
    return {
        "time_s": elapsed,
        "error": sol.error,
        "iterations": sol.iterations,
        "converged": bool(sol.converged),
        "method": sol.solver,
    }


def _warm_up(problem) -> None:
    for solver in SOLVERS:
        get_solver(solver)(problem, tol=1e-2, max_iter=2)


def _table(rows: list[dict], tolerances: tuple[float, ...]) -> str:
    head = "| problem | contacts | solver | " + " | ".join(f"tol {t:.0e}" for t in tolerances)
    lines = [head + " |", "|" + "---|" * (3 + len(tolerances))]
    keys = sorted({(r["problem"], r["solver"]) for r in rows}, key=lambda k: (k[0], k[1]))
    for problem, solver in keys:
        cells = []
        nc = ""
        for tol in tolerances:
            match = [r for r in rows if r["problem"] == problem and r["solver"] == solver and r["tol"] == tol]
            if not match:
                cells.append("–")
                continue
            r = match[0]
            nc = r["n_contacts"]
            mark = "" if r["converged"] else " ✗"
            cells.append(f"{r['error']:.1e} / {r['iterations']} it / {r['time_s'] * 1e3:.1f} ms{mark}")
        lines.append(f"| {problem} | {nc} | {solver} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _summary(rows: list[dict]) -> str:
    lines = [
        "| solver | tol | solved | shifted geometric mean time (solved and not) |",
        "|---|---|---|---|",
    ]
    for solver in SOLVERS:
        for tol in TOLERANCES:
            sel = [r for r in rows if r["solver"] == solver and r["tol"] == tol]
            if not sel:
                continue
            ok = sum(r["converged"] for r in sel)
            sgm = shifted_geometric_mean([r["time_s"] for r in sel])
            lines.append(f"| {solver} | {tol:.0e} | {ok}/{len(sel)} | {sgm * 1e3:.1f} ms |")
    return "\n".join(lines)


def run(quick: bool) -> Section:
    files = sorted(FCLIB_DIR.glob("*.hdf5"))
    if not files:
        return Section(
            title="FCLib problems",
            markdown=f"Skipped: no FCLib problems in `{FCLIB_DIR}` (the ../shared folder).",
        )
    reps = 1 if quick else 3
    problems = [(path.stem, read_fclib(path)) for path in files]
    _warm_up(problems[0][1].problem)
    rows: list[dict] = []
    for name, fc in problems:
        for solver in SOLVERS:
            for tol in TOLERANCES:
                rec = _time_solve(fc.problem, solver, tol, reps)
                rows.append(
                    {
                        "problem": name,
                        "kind": fc.kind,
                        "n_contacts": fc.n_contacts,
                        "solver": solver,
                        "tol": tol,
                        **rec,
                    }
                )
    parts = [
        "Each cell: error reached / iterations / time (best of "
        f"{reps}); ✗ = tolerance not reached within the cap "
        f"(NSGS {MAX_ITER['nsgs']} sweeps, SOCP {MAX_ITER['socp']} rounds). Error: the FCLib "
        "natural-map residual, ρ = 1, relative to max(‖q‖, ‖r‖, ‖u‖). Iterations: NSGS sweeps; "
        "SOCP rounds (one SOCP + ≤ 50·4ᵏ polishing sweeps each); auto = 100 NSGS sweeps + "
        "SOCP rounds.",
        "",
        _table(rows, TOLERANCES),
        "",
        _summary(rows),
    ]
    if not quick:
        stack_rows: list[dict] = []
        for n_boxes, mu in ((3, 0.3), (8, 0.3), (8, 1.0)):
            problem = box_stack(n_boxes, 10.0, mu, seed=n_boxes)
            name = f"stack-{n_boxes}x-ratio10-mu{mu}"
            for solver in SOLVERS:
                rec = _time_solve(problem, solver, 1e-8, 1)
                stack_rows.append(
                    {
                        "problem": name,
                        "kind": "synthetic",
                        "n_contacts": problem.n_contacts,
                        "solver": solver,
                        "tol": 1e-8,
                        **rec,
                    }
                )
        rows += stack_rows
        parts += [
            "",
            "Box stacks (4 corner contacts per interface, W of half rank, mass ratio 10): where NSGS stalls.",
            "",
            _table(stack_rows, (1e-8,)),
        ]
    return Section(title="FCLib problems", markdown="\n".join(parts), rows=rows)
