"""Pins in holes and pegs in bores in the engine: the step's time against its error, target ≥ 1 kHz real time.

Each step of a fixture with pins detects every pin's and bore's contacts in closed form (compiled:
:mod:`fixplan.geometry._pin_kernels`, slots by :mod:`fixplan.engine.pin_slots`) before the
compiled Moreau–Jean step, from Python: what the haptic loop calls every 1 ms tick. Cases:

- ``housing seated``: problems/housing-2-pins at its located pose, pushed 10 N toward the round pin
  and 20 N down (3 rests, P1 touching at two points, P2's lands within the margin or not);
- ``housing engaging``: the housing 12.5 mm above its located pose (its holes 0.5 mm above the pins'
  tips), 0.36 mm off, pushed down 20 N: the tips on the holes' chamfers, then the sides, then the
  rests (every kind of contact in turn);
- ``shaft in bore``: problems/shaft-in-bore (two-point contact) pushed 1 N down its bore;
- ``peg drop``: a peg dropped 3 mm above a chamfered bore, 0.6 mm off axis, onto its bottom;
- ``housing seated, mesh part`` and ``housing engaging, mesh part``: the first two with the box
  written as a 12-triangle mesh (the rests found on its triangles, the pins in the analytic holes,
  in one compiled call: :mod:`fixplan.engine.mesh_slots`).

Every step is timed alone (``time.perf_counter`` around ``Simulator.step``, garbage collection
off, after 200 warm-up steps on a copy); the figures are the mean, median and 95th percentile, and
the steps over 1 ms. The error beside them: the deepest penetration and the worst FCLib residual.
"""

from __future__ import annotations

import copy
import gc
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np
from run import Section

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.spatial import Pose

ROOT = Path(__file__).resolve().parents[1]
PERIOD_S = 1e-3  # the haptic loop's tick
PEG_DROP = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "peg-drop"
    [workpiece]
    shape = "cylinder"
    radius = 0.01
    length = 0.06
    mass = 0.1
    start = { position = [0.0006, 0.0002, 0.033], rpy_deg = [0.0, 0.0, 0.0] }
    [[bore]]
    name = "B1"
    position = [0.0, 0.0, 0.0]
    axis = [0.0, 0.0, 1.0]
    diameter = 0.0202
    depth = 0.03
    chamfer = 0.001
    friction = 0.2
    """
)


def _housing_as_mesh() -> fixplan.Fixture:
    """problems/housing-2-pins.toml with its box written as a 12-triangle STL (mm): the same holes, rests and pins."""
    from fixplan.geometry.cells import box_cells, cell_surface
    from fixplan.geometry.mesh import stl_bytes

    text = (ROOT / "problems" / "housing-2-pins.toml").read_text(encoding="utf-8")
    box = 'shape = "box"\nsize = [0.12, 0.08, 0.03]'
    if box not in text:
        raise ValueError("problems/housing-2-pins.toml no longer has the box this benchmark rewrites")
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "housing.stl").write_bytes(stl_bytes(*cell_surface(*box_cells((120.0, 80.0, 30.0), 1))))
        mesh = text.replace(box, 'shape = "mesh"\nfile = "housing.stl"\nunits = "mm"')
        return fixplan.loads(mesh, source="housing-2-pins-mesh", base_dir=Path(tmp))


def cases() -> list[tuple[str, Simulator, np.ndarray]]:
    out = []
    for label, housing in (
        ("", fixplan.load(ROOT / "problems" / "housing-2-pins.toml")),
        (", mesh part", _housing_as_mesh()),
    ):
        goal = housing.goal
        seated = Simulator(housing)
        seated.set_state(goal)
        engaging = Simulator(housing)
        engaging.set_state(Pose(goal.R_world_body, goal.p_world + np.array([0.0003, 0.0002, 0.0125])))
        out += [
            (f"housing seated{label}", seated, np.array([10.0, 0.0, -20.0, 0.0, 0.0, 0.0])),
            (f"housing engaging{label}", engaging, np.array([0.0, 0.0, -20.0, 0.0, 0.0, 0.0])),
        ]
    shaft = Simulator(fixplan.load(ROOT / "problems" / "shaft-in-bore.toml"))
    drop = Simulator(fixplan.loads(PEG_DROP))
    return [
        *out[:2],
        ("shaft in bore", shaft, np.array([0.0, 0.0, -1.0, 0.0, 0.0, 0.0])),
        ("peg drop", drop, np.zeros(6)),
        *out[2:],
    ]


def _pin_contacts(sim: Simulator) -> int:
    """How many pin and bore contacts the last step had (a mesh part's: its compiled step's count)."""
    stepper = sim._mesh_stepper  # noqa: SLF001 - the benchmark reports how many contacts the step had
    if stepper is not None:
        return int(stepper.pin_count[0])
    last = sim._pin_last  # noqa: SLF001
    return len(last) if last is not None else 0


def time_steps(sim: Simulator, wrench: np.ndarray, n: int) -> tuple[np.ndarray, float, int]:
    """Each step's wall time [s], the worst residual and the most slots handed over in a step."""
    warm = copy.deepcopy(sim)
    for _ in range(200):
        warm.step(wrench)
    out = np.empty(n)
    worst, most = 0.0, 0
    gc.disable()
    try:
        for k in range(n):
            t0 = time.perf_counter()
            info = sim.step(wrench)
            out[k] = time.perf_counter() - t0
            worst = max(worst, info.error)
            most = max(most, _pin_contacts(sim))
    finally:
        gc.enable()
    return out, worst, most


def run(quick: bool) -> Section:
    n = 500 if quick else 3000
    rows: list[dict] = []
    lines = [
        f"Engine steps with pins and bores, each timed from Python (detection + compiled step), {n} steps of 1 ms "
        "per case; target: a mean step ≤ 1 ms (≥ 1 kHz real time).",
        "",
        "| case | steps | mean [µs] | p50 [µs] | p95 [µs] | over 1 ms | rate [kHz] | most contacts | max penetration [m] "
        "| worst residual |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, sim, wrench in cases():
        t, worst, most = time_steps(sim, wrench, n)
        mean, p50, p95 = float(t.mean()), float(np.median(t)), float(np.percentile(t, 95))
        over = int((t > PERIOD_S).sum())
        rows.append(
            {
                "case": name,
                "steps": n,
                "mean_us": 1e6 * mean,
                "p50_us": 1e6 * p50,
                "p95_us": 1e6 * p95,
                "over_period": over,
                "rate_khz": 1e-3 / mean,
                "most_pin_contacts": most,
                "max_penetration_m": sim.max_penetration_m,
                "worst_residual": worst,
            }
        )
        lines.append(
            f"| {name} | {n} | {1e6 * mean:.0f} | {1e6 * p50:.0f} | {1e6 * p95:.0f} | {over} | {1e-3 / mean:.2f} "
            f"| {most} | {sim.max_penetration_m:.2g} | {worst:.2g} |"
        )
    return Section("Pins and bores in the engine", "\n".join(lines), rows)
