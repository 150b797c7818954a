"""The executor's push search with an arm: what searching within its joint-torque box costs per call.

With a ``[robot]`` the executor (``fixplan/planner/execute.py``) searches every push at 200 Hz
within the arm's joint-torque box at the part's pose (``Executor._search``): the joints followed
by warm-started inverse kinematics, the box built, the push first sought without the box's rows
while the box does not bind. Timed on ``problems/box-3-2-1-arm6.toml`` (the part sliding on B1,
B2, B3 toward E1, the pose moved 10 µm between calls, interleaved in a turning order so that
the machine's load and the warm caches fall on all three alike), the median per call of:

- the search without the arm (what the executor did before it respected the arm);
- ``Executor._search`` where the box does not bind (its usual case);
- ``Executor._search`` with the box's rows in every program (where the box binds).

Rows (``results/bench_robot.csv``): one per variant with the least, the median and the 90th
percentile [ms] (on a shared machine the least is the cost, the others add the load).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from run import Section

import fixplan
from fixplan.jamming.search import search_wrench
from fixplan.planner.execute import Executor
from fixplan.spatial import Pose

FIXTURE = Path(__file__).resolve().parents[1] / "problems" / "box-3-2-1-arm6.toml"
EST = ["B1", "B2", "B3"]
OPTIONS = {"objective": "effort", "friction_margin": 0.1, "max_accel_factor": 3.0, "confirm": False}


def run(quick: bool) -> Section:
    fx = fixplan.load(FIXTURE)
    goal = fx.goal_pose
    motion = np.array([-0.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    free = Executor(fx, frozenset(EST), [])
    bound = Executor(fx, frozenset(EST), [])
    n = 100 if quick else 400
    times: dict[str, list[float]] = {"without the arm": [], "with the arm (box not binding)": [], "within the box": []}
    calls = {
        "without the arm": lambda pose: search_wrench(fx, motion, EST, pose=pose, **OPTIONS),
        "with the arm (box not binding)": lambda pose: free._search(0.0, pose, motion, EST, **OPTIONS),
        "within the box": lambda pose: bound._search(0.0, pose, motion, EST, **OPTIONS),
    }
    keys = list(calls)
    for i in range(n + 20):
        pose = Pose(goal.R_world_body, goal.p_world + np.array([0.003 - 1e-5 * i, 0.0, 0.0]))
        bound._box_binds = True
        for j in range(3):  # the order turns every call: none profits from another's warm caches
            key = keys[(i + j) % 3]
            t0 = time.perf_counter()
            res = calls[key](pose)
            dt = time.perf_counter() - t0
            if not res.found:
                raise RuntimeError("a search found no push on box-3-2-1-arm6")
            if i >= 20:  # the first calls warm the caches
                times[key].append(dt)
    rows = [
        {
            "variant": key,
            "min_ms": 1e3 * float(np.min(v)),
            "median_ms": 1e3 * float(np.median(v)),
            "p90_ms": 1e3 * float(np.percentile(v, 90)),
            "calls": len(v),
        }
        for key, v in times.items()
    ]
    lines = [
        f"The executor's push search on `problems/box-3-2-1-arm6.toml`, {n} calls each, interleaved:",
        "",
        "| variant | least [ms] | median [ms] | p90 [ms] |",
        "|---|---|---|---|",
        *(f"| {r['variant']} | {r['min_ms']:.2f} | {r['median_ms']:.2f} | {r['p90_ms']:.2f} |" for r in rows),
    ]
    return Section("Robot: the executor's search within the arm's box", "\n".join(lines), rows)
