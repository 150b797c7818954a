"""Generated plane-2-pins fixtures: insertions planned, verified and robust, and the housing's solve time.

A box on 3 rests loaded onto a round and a diamond pin through two bored holes, drawn by
``fixplan generate plane-2-pins`` (each pin's length on its own, so either pin may engage first):
40 fixtures of a development seed and 40 of a held-out seed (reported apart; do not tune on the
held-out one), each solved as a user would: one whole ``fixplan solve FILE --json`` process, after
one warm-up run per set. ``planned`` means the insertion's simulated load (the haptic loop, 1 kHz)
seated the part; ``unverified``, a timeout, a crash or a refused file count as failures.

Robust: the first ``ROBUST_PER_SET`` verified fixtures of each set through ``fixplan robust FILE
--samples N --seed 0 --json`` (the pins' perturbations: friction μ(1 ± 0.2), the start's pose
errors larger than the clearance, which the chamfers must capture; operator force noise and
latency), pooled and per fixture with the Wilson 95 % interval.

The housing (``problems/housing-2-pins.toml``): ``fixplan solve --json`` as a whole process,
``HOUSING_RUNS`` times after a warm-up, its median wall time.

Targets: planned and verified ≥ 95 % per set, robust ≥ 95 % pooled; the housing's solve ≤ 5 s median.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from bench_generated import _exe, _failed, _git_state, _pct, _run_json, _short, _solve, wilson
from bench_robust import _robust, robust_row
from run import Section

from fixplan.generate import generate

ROOT = Path(__file__).resolve().parents[1]
SETS = (("plane-2-pins", 2031), ("plane-2-pins held-out", 9301))
COUNT, QUICK_COUNT = 40, 6
ROBUST_PER_SET, ROBUST_SAMPLES, QUICK_ROBUST_SAMPLES = 5, 20, 4
HOUSING_RUNS = 5
TARGET_VERIFIED = 0.95
TARGET_ROBUST = 0.95
TARGET_HOUSING_S = 5.0


def run(quick: bool) -> Section:
    count = QUICK_COUNT if quick else COUNT
    samples = QUICK_ROBUST_SAMPLES if quick else ROBUST_SAMPLES
    code = _git_state()
    load = [os.getloadavg()[0]]
    rows: list[dict[str, Any]] = []
    robust_rows: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fixplan-pins-") as tmp:
        for label, seed in SETS:
            paths = []
            for g in generate("plane-2-pins", count, seed):
                path = Path(tmp) / f"{g.name}.toml"
                path.write_text(g.toml_text)
                paths.append(path)
            _run_json([_exe(), "solve", str(paths[0]), "--json"], 600.0)  # warm-up, not counted
            for path in paths:
                print(f"[bench_pins_generated] {path.stem} ...", file=sys.stderr, flush=True)
                r = _solve(path)
                print(f"[bench_pins_generated]   {r['status']} {r['wall_s']:.1f} s", file=sys.stderr, flush=True)
                rows.append({"set": label, "seed": seed, "name": path.stem, **r})
            verified = [p for p, r in zip(paths, rows[-len(paths) :], strict=True) if r["status"] == "planned"]
            for path in verified[:ROBUST_PER_SET]:
                print(f"[bench_pins_generated] robust {path.stem} ...", file=sys.stderr, flush=True)
                robust_rows.append({"set": label, "name": path.stem, **_robust(path, samples)})
        housing = ROOT / "problems" / "housing-2-pins.toml"
        _run_json([_exe(), "solve", str(housing), "--json"], 600.0)  # warm-up
        housing_walls = []
        housing_status = []
        for _ in range(HOUSING_RUNS):
            wall, out, _code, err = _run_json([_exe(), "solve", str(housing), "--json"], 600.0)
            housing_walls.append(wall)
            housing_status.append(out.get("status") if out else err)
    load.append(os.getloadavg()[0])
    total_s = time.perf_counter() - t0
    md = _markdown(rows, robust_rows, samples, housing_walls, housing_status, code, load, total_s, quick)
    csv_rows = [
        {k: r.get(k) for k in ("set", "seed", "name", "status", "proven", "n_transitions", "replans")}
        | {k: None if r.get(k) is None else round(float(r[k]), 3) for k in ("plan_s", "verify_s", "wall_s")}
        | {"reason": _short(r.get("reason") or "", 150)}
        for r in rows
    ]
    return Section("Generated plane-2-pins fixtures: insertions planned, verified and robust", md, csv_rows)


def _markdown(
    rows: list[dict[str, Any]],
    robust_rows: list[dict[str, Any]],
    samples: int,
    housing_walls: list[float],
    housing_status: list[Any],
    code: str,
    load: list[float],
    total_s: float,
    quick: bool,
) -> str:
    from run import machine_markdown

    lines = [
        __doc__.split("\n", 1)[1].strip(),
        "",
        machine_markdown(),
        f"- code: {code}",
        f"- {'quick run: ' if quick else ''}{total_s / 60:.1f} min in all; load average {load[0]:.1f} at the start, "
        f"{load[-1]:.1f} at the end (2 cores; wall times are noisy)",
        "",
        "| set | fixtures | planned and verified | proven infeasible | failed without proof | median wall [s] | p95 wall [s] |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    verdicts = []
    for label, seed in SETS:
        fam = [r for r in rows if r["set"] == label]
        if not fam:
            continue
        n = len(fam)
        walls = np.array([r["wall_s"] for r in fam])
        planned = sum(r["status"] == "planned" for r in fam)
        proven = sum(r["status"] == "infeasible" and bool(r["proven"]) for r in fam)
        failed = sum(_failed(r) for r in fam)
        lines.append(
            f"| {label} (seed {seed}) | {n} | {_pct(planned, n)} | {_pct(proven, n)} | {_pct(failed, n)} | "
            f"{np.median(walls):.2f} | {np.percentile(walls, 95):.2f} |"
        )
        met = planned / n >= TARGET_VERIFIED
        verdicts.append(
            f"- {label}: planned and verified **{100 * planned / n:.1f} %** against ≥ {TARGET_VERIFIED:.0%} "
            f"(**{'met' if met else 'missed'}**)"
        )
    failures = [r for r in rows if r["status"] != "planned"]
    if failures:
        lines += ["", "Not planned and verified:", ""]
        lines += [f"- {r['name']}: `{r['status']}` — {_short(r.get('reason') or '', 160)}" for r in failures]
    lines += [
        "",
        f"Robust ({samples} perturbed worlds each, seed 0):",
        "",
        "| set | fixture | succeeded / samples | 95 % interval | failure causes | wall [s] |",
        "|---|---|---:|---|---|---:|",
    ]
    k = n_all = 0
    for r in robust_rows:
        lines.append(robust_row(r))
        if r.get("samples") is None:
            continue
        k, n_all = k + r["succeeded"], n_all + r["samples"]
    if n_all:
        lo, hi = wilson(k, n_all)
        met = k / n_all >= TARGET_ROBUST and all(r.get("samples") for r in robust_rows)
        verdicts.append(
            f"- robust, pooled: **{k}/{n_all} ({100 * k / n_all:.1f} %)**, 95 % interval {lo:.3f}–{hi:.3f}, against "
            f"≥ {TARGET_ROBUST:.0%} (**{'met' if met else 'missed'}**)"
        )
    replays = [r for r in robust_rows if r.get("replay")]
    if replays:
        lines += ["", "Replays of robust failures:", ""] + [f"- {r['name']}: `{r['replay']}`" for r in replays]
    med = float(np.median(housing_walls))
    lines += [
        "",
        f"The housing: `fixplan solve problems/housing-2-pins.toml --json`, {len(housing_walls)} runs: "
        f"{', '.join(f'{w:.2f}' for w in housing_walls)} s (status {', '.join(sorted({str(s) for s in housing_status}))}).",
    ]
    verdicts.append(
        f"- the housing's solve: median **{med:.2f} s** against ≤ {TARGET_HOUSING_S:g} s "
        f"(**{'met' if med <= TARGET_HOUSING_S else 'missed'}**)"
    )
    lines += ["", "Targets:", "", *verdicts]
    return "\n".join(lines)


if __name__ == "__main__":
    print(run("--quick" in sys.argv).markdown)
