"""fixplan's contact engine against MuJoCo, side by side in one run.

Same scenes, same step, same initial states:

1. **six-locator box**: the default fixture at its goal pose pushed into its six locators with
   5 N along (-1,-1,-1)/√3 through the centre of mass, dt = 1 ms: steps per second and the
   steady-state penetration;
2. **incline stick**: θ = 20°, μ = 0.5, a box on three point locators under tilted gravity:
   displacement (creep) after 2 s;
3. **incline slide**: θ = 30°, μ = 0.3: acceleration error against a = g (sin θ − μ cos θ) over
   the first 0.1 s and lift-off (largest normal displacement);
4. **speed against error** (incline slide): fixplan over dt × NSGS tolerance, MuJoCo over dt.

MuJoCo gets equivalent MJCF scenes built here: a free box body (same size, mass, inertia), the
locators as fixed sphere geoms (5 mm tips for the default fixture; a point locator becomes a
1e-4 m sphere whose top touches the box), ``cone="elliptic"``, condim 3 (4 for soft fingers),
friction μ on both geoms (MuJoCo combines with max), default solref/solimp, Euler integrator,
Newton solver. The push is ``qfrc_applied`` (= the same force at the centre of mass).
"""

from __future__ import annotations

import math
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from run import Section

import fixplan
from fixplan.engine.simulator import Simulator
from fixplan.spatial import Pose, matrix_from_quaternion_wxyz, quaternion_wxyz_from_matrix

try:
    import mujoco
    from mujoco import rollout as mj_rollout
except ImportError:  # pragma: no cover - the benchmark still reports fixplan's side
    mujoco = None
    mj_rollout = None

G = 9.81
DT = 1e-3
PUSH_N = 5.0
TOL = 1e-8  # [simulation] tolerance of the default fixture; used for items 1–3
MJ_POINT_RADIUS = 1e-4  # MuJoCo sphere standing in for a point locator
NEVER = 10**9  # record_every: no samples inside the timed run

BOX3 = """format = 1
[scene]
name = "{name}"
gravity = {gravity}
[workpiece]
shape = "box"
size = [0.2, 0.1, 0.05]
mass = 2.0
start = {{ position = [0.0, 0.0, 0.025] }}
[simulation]
timestep = {dt}
tolerance = {tol}
restitution = 0.0
{locators}"""


# ---------------------------------------------------------------------------------------------
# scenes
# ---------------------------------------------------------------------------------------------
def incline_gravity(theta_deg: float) -> tuple[float, float, float]:
    th = math.radians(theta_deg)
    return (G * math.sin(th), 0.0, -G * math.cos(th))


def box_on_three(name: str, mu: float, gravity: tuple[float, float, float], dt: float = DT, tol: float = TOL):
    """The box of tests/engine/test_validation.py on three point locators (its bottom face at z = 0)."""
    locs = "".join(
        f'[[locator]]\nname = "B{i}"\nposition = [{x}, {y}, 0.0]\nfriction = {mu}\n'
        for i, (x, y) in enumerate([(-0.06, -0.03), (0.06, -0.03), (0.0, 0.03)], 1)
    )
    g = "[" + ", ".join(f"{x:.17g}" for x in gravity) + "]"
    return fixplan.loads(BOX3.format(name=name, gravity=g, dt=dt, tol=tol, locators=locs))


def _fmt(x: Any) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.atleast_1d(x))


def mjcf(fx, pose: Pose, dt: float) -> str:
    """An MJCF scene equivalent to ``fx`` with the workpiece (a box) at ``pose``."""
    wp = fx.workpiece
    half = wp.shape.half
    R = np.asarray(pose.R_world_body, dtype=float)
    geoms = []
    for loc in fx.locators:
        condim = 4 if loc.torsion_m > 0 else 3
        radius = loc.radius_m
        centre = np.asarray(loc.p_world, dtype=float)
        if radius <= 0.0:  # a point: a tiny sphere whose top is the point, behind the face it touches
            radius = MJ_POINT_RADIUS
            pb = R.T @ (centre - pose.p_world)
            k = int(np.argmax(np.abs(pb) / half))
            n_body = np.zeros(3)
            n_body[k] = math.copysign(1.0, pb[k])
            centre = centre + radius * (R @ n_body)
        geoms.append(
            f'    <geom name="{loc.name}" type="sphere" size="{radius:.17g}" pos="{_fmt(centre)}" '
            f'friction="{loc.friction:.17g} {loc.friction * loc.torsion_m:.17g} 0" condim="{condim}"/>'
        )
    mu = max(loc.friction for loc in fx.locators)  # all locators share μ in these scenes
    quat = quaternion_wxyz_from_matrix(R)
    inertia = np.diag(wp.inertia_body)
    return f"""<mujoco model="{fx.name}">
  <option timestep="{dt:.17g}" cone="elliptic" gravity="{_fmt(fx.gravity)}"/>
  <worldbody>
{chr(10).join(geoms)}
    <body name="workpiece" pos="{_fmt(pose.p_world)}" quat="{_fmt(quat)}">
      <freejoint/>
      <inertial pos="{_fmt(wp.com_body)}" mass="{wp.mass_kg:.17g}" diaginertia="{_fmt(inertia)}"/>
      <geom name="box" type="box" size="{_fmt(half)}" friction="{mu:.17g} 0 0" condim="3"/>
    </body>
  </worldbody>
</mujoco>
"""


class MjScene:
    """One MuJoCo model + data with a constant force at the centre of mass (``qfrc_applied``)."""

    def __init__(self, fx, pose: Pose, dt: float, force: np.ndarray):
        self.fx = fx
        self.xml = mjcf(fx, pose, dt)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        self.p0 = np.asarray(pose.p_world, dtype=float)
        self.q0 = quaternion_wxyz_from_matrix(pose.R_world_body)
        self.qfrc = np.zeros(6)
        self.qfrc[:3] = force  # through the centre of mass: no moment
        self.names = [loc.name for loc in fx.locators]
        self.gid = {mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, n): n for n in self.names}

    def reset(self) -> None:
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:3] = self.p0
        d.qpos[3:7] = self.q0
        d.qvel[:] = 0.0
        d.qfrc_applied[:] = self.qfrc
        mujoco.mj_forward(m, d)

    def time_loop(self, n: int) -> float:
        """``mj_step`` called from Python ``n`` times; wall seconds."""
        self.reset()
        m, d, step = self.model, self.data, mujoco.mj_step
        t0 = time.perf_counter()
        for _ in range(n):
            step(m, d)
        return time.perf_counter() - t0

    def time_rollout(self, n: int) -> tuple[float, np.ndarray]:
        """``mujoco.rollout`` (C++ loop, calling thread) for ``n`` steps; wall seconds and states."""
        self.reset()
        m, d = self.model, self.data
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS.value
        x0 = np.empty((1, mujoco.mj_stateSize(m, spec)))
        mujoco.mj_getState(m, d, x0[0], spec)
        ctrl = self.qfrc.reshape(1, 1, 6).copy()
        out = np.empty((1, n, x0.shape[1]))
        cspec = mujoco.mjtState.mjSTATE_QFRC_APPLIED.value
        t0 = time.perf_counter()
        mj_rollout.rollout(m, d, x0, ctrl, control_spec=cspec, nstep=n, state=out)
        return time.perf_counter() - t0, out[0]

    def record(self, n: int) -> dict[str, np.ndarray]:
        """``n`` steps with every sample kept (untimed): time, position, quaternion, velocity, deepest contact."""
        self.reset()
        m, d = self.model, self.data
        t = np.zeros(n + 1)
        pos = np.zeros((n + 1, 3))
        quat = np.zeros((n + 1, 4))
        vel = np.zeros((n + 1, 6))
        pen = np.zeros(n + 1)
        pos[0], quat[0] = d.qpos[:3], d.qpos[3:7]
        for s in range(1, n + 1):
            mujoco.mj_step(m, d)
            t[s] = d.time
            pos[s], quat[s], vel[s] = d.qpos[:3], d.qpos[3:7], d.qvel
            pen[s] = max(0.0, -float(d.contact.dist.min())) if d.ncon else 0.0
        mujoco.mj_forward(m, d)  # contacts at the final pose
        return {"t": t, "p": pos, "quat": quat, "v": vel, "pen": pen}

    def steady_contacts(self) -> tuple[float, dict[str, float]]:
        """Deepest penetration and per-locator normal force at the current (forwarded) state."""
        m, d = self.model, self.data
        pen = max(0.0, -float(d.contact.dist.min())) if d.ncon else 0.0
        loads = dict.fromkeys(self.names, 0.0)
        f6 = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            name = self.gid.get(c.geom1, self.gid.get(c.geom2))
            if name is not None:
                mujoco.mj_contactForce(m, d, i, f6)
                loads[name] += float(f6[0])
        return pen, loads


def _best(reps: int, fn: Callable[[], tuple[float, Any]], budget_s: float = 0.0) -> tuple[float, Any]:
    """Min wall time of ``fn`` over ``reps`` calls (more, up to 300, while under ``budget_s``)."""
    best, out, total, k = math.inf, None, 0.0, 0
    while k < reps or (total < budget_s and k < 300):
        wall, out = fn()
        best = min(best, wall)
        total += wall
        k += 1
    return best, out


def _fixplan_run(fx, pose: Pose, duration: float, wrench, dt: float, tol: float, every: int = NEVER):
    sim = Simulator(fx, dt=dt, tolerance=tol)
    sim.set_state(pose)
    t0 = time.perf_counter()
    traj = sim.run(duration, wrench, record_every=every)
    return time.perf_counter() - t0, (sim, traj)


def _support_gaps(fx, p: np.ndarray, Rs: np.ndarray) -> np.ndarray:
    """Gap between each point locator and the box's bottom face (body −z) for each sample [m]."""
    half_z = fx.workpiece.shape.half[2]
    locs = np.array([loc.p_world for loc in fx.locators])
    out = np.zeros((len(p), len(locs)))
    for s in range(len(p)):
        pb = (locs - p[s]) @ Rs[s]  # rows: Rᵀ (q − p)
        out[s] = -half_z - pb[:, 2]
    return out


def _slide_metrics(fx, t: np.ndarray, p: np.ndarray, Rs: np.ndarray, vx: np.ndarray, a: float) -> dict[str, float]:
    """Acceleration and velocity errors against v = a t, normal displacement and support lift-off."""
    tt, vv = t[1:], vx[1:]
    slope = float(np.polyfit(tt, vv, 1)[0])
    dz = p[:, 2] - p[0, 2]
    gaps = _support_gaps(fx, p, Rs)
    return {
        "accel_rel_err": abs(slope - a) / a,
        "vel_rel_err": abs(vv[-1] - a * tt[-1]) / (a * tt[-1]),
        "max_vel_dev_rel": float(np.max(np.abs(vv - a * tt)) / (a * tt[-1])),
        "liftoff_m": float(np.max(np.abs(dz))),
        "rise_m": float(max(0.0, dz.max())),
        "support_gap_m": float(max(0.0, gaps.max())),
    }


def _row(item: str, engine: str, method: str, **kw: Any) -> dict[str, Any]:
    row: dict[str, Any] = {
        "item": item,
        "engine": engine,
        "method": method,
        "dt_s": DT,
        "tolerance": float("nan"),
        "sim_time_s": float("nan"),
        "steps": 0,
        "wall_s_best": float("nan"),
        "steps_per_s": float("nan"),
        "wall_s_per_sim_s": float("nan"),
        "penetration_steady_m": float("nan"),
        "penetration_max_m": float("nan"),
        "creep_m": float("nan"),
        "creep_last_1s_m": float("nan"),
        "normal_disp_m": float("nan"),
        "accel_rel_err": float("nan"),
        "vel_rel_err": float("nan"),
        "max_vel_dev_rel": float("nan"),
        "liftoff_m": float("nan"),
        "rise_m": float("nan"),
        "support_gap_m": float("nan"),
        "mean_iterations": float("nan"),
        "note": "",
    }
    for k, v in kw.items():
        assert k in row, k
        row[k] = v
    if row["steps"] and row["wall_s_best"] == row["wall_s_best"]:
        row["steps_per_s"] = row["steps"] / row["wall_s_best"]
        row["wall_s_per_sim_s"] = row["wall_s_best"] / row["sim_time_s"]
    return row


def _loads(d: dict[str, float]) -> str:
    return " ".join(f"{k} {v:.2f}" for k, v in d.items())


# ---------------------------------------------------------------------------------------------
# 1. the six-locator box
# ---------------------------------------------------------------------------------------------
def six_locator_box(quick: bool, reps: int) -> tuple[list[dict], dict[str, Any]]:
    fx = fixplan.load(fixplan.default_fixture_path())
    goal = fx.goal
    push = -PUSH_N * np.ones(3) / math.sqrt(3.0)
    wrench = np.concatenate([push, np.zeros(3)])
    T = 5.0 if quick else 20.0
    n = int(round(T / DT))
    item = "six-locator box"
    rows = []
    info: dict[str, Any] = {}

    # warm-up: load (or build) numba's cache outside every timed run
    t0 = time.perf_counter()
    _fixplan_run(fx, goal, 0.05, wrench, DT, TOL)
    info["warmup_s"] = time.perf_counter() - t0

    # fixplan and MuJoCo interleaved, so that load from other processes hits both alike
    sc = None
    if mujoco is not None:
        sc = MjScene(fx, goal, DT, push)
        sc.time_loop(100)  # warm-up
        sc.time_rollout(100)
    best = {"fixplan": math.inf, "kernel": math.inf, "loop": math.inf, "rollout": math.inf}
    states = None
    for _ in range(reps):
        w, (sim, traj) = _fixplan_run(fx, goal, T, wrench, DT, TOL)
        best["fixplan"] = min(best["fixplan"], w)
        best["kernel"] = min(best["kernel"], traj.wall_time_s)
        if sc is not None:
            best["loop"] = min(best["loop"], sc.time_loop(n))
            w, states = sc.time_rollout(n)
            best["rollout"] = min(best["rollout"], w)
    wall = best["fixplan"]
    gaps_final = np.array([c.gap_m for c in sim.contacts()])
    # accuracy from a recorded run (gaps are start-of-step gaps; max_penetration_m is the engine's own)
    _, (sim_r, traj_r) = _fixplan_run(fx, goal, min(T, 2.0), wrench, DT, TOL, every=1)
    pen_max = max(sim_r.max_penetration_m, float(max(0.0, -np.min(traj_r.gap))))
    pen_steady = float(max(0.0, -gaps_final.min()))
    fp_loads = {c.name: c.normal_force_N for c in sim.contacts()}
    rows.append(
        _row(
            item,
            "fixplan",
            "Simulator.run (compiled loop)",
            tolerance=TOL,
            sim_time_s=T,
            steps=traj.steps,
            wall_s_best=wall,
            penetration_steady_m=pen_steady,
            penetration_max_m=pen_max,
            mean_iterations=float(np.mean(traj_r.iterations[1:])),
            note=f"engine-reported max_penetration_m {sim_r.max_penetration_m:.3g}; best kernel-only wall (Trajectory.wall_time_s) {best['kernel']:.4f} s; loads [N] {_loads(fp_loads)}",
        )
    )
    info["fixplan_loads"] = fp_loads
    info["fixplan_engine_pen"] = sim_r.max_penetration_m

    # the same engine stepped from Python, one call per step (like the mj_step loop)
    n_py = min(n, 2000)

    def py_steps():
        s = Simulator(fx, dt=DT, tolerance=TOL)
        s.set_state(goal)
        t0 = time.perf_counter()
        for _ in range(n_py):
            s.step(wrench)
        return time.perf_counter() - t0, s

    wall_py, _ = _best(reps, py_steps)
    rows.append(
        _row(
            item,
            "fixplan",
            "Simulator.step from Python",
            tolerance=TOL,
            sim_time_s=n_py * DT,
            steps=n_py,
            wall_s_best=wall_py,
        )
    )

    if sc is not None:
        wall_loop, wall_roll = best["loop"], best["rollout"]
        rec = sc.record(n)
        pen_steady_mj, mj_loads = sc.steady_contacts()
        qpos_roll = states[-1, 1:8]
        agree = float(np.max(np.abs(qpos_roll - np.concatenate([rec["p"][-1], rec["quat"][-1]]))))
        common = {
            "sim_time_s": T,
            "steps": n,
            "penetration_steady_m": pen_steady_mj,
            "penetration_max_m": float(rec["pen"].max()),
        }
        rows.append(
            _row(
                item,
                "MuJoCo",
                "mj_step loop in Python",
                wall_s_best=wall_loop,
                **common,
                note=f"loads [N] {_loads(mj_loads)}",
            )
        )
        rows.append(
            _row(
                item,
                "MuJoCo",
                "mujoco.rollout (C++ loop)",
                wall_s_best=wall_roll,
                **common,
                note=f"final qpos vs mj_step loop: max |diff| {agree:.1e}",
            )
        )
        info["mj_loads"] = mj_loads
        info["mj_opt"] = sc.model.opt
    return rows, info


# ---------------------------------------------------------------------------------------------
# 1b. the same push through the command a user runs: `fixplan simulate`, whole process
# ---------------------------------------------------------------------------------------------
CLI_LONG_S, CLI_SHORT_S = 22.0, 2.0


def _simulate_process(duration: float, wrench: str) -> tuple[float, float]:
    """Wall time and CPU time (user + system) of one `fixplan simulate` process."""
    exe = str(Path(sys.executable).with_name("fixplan"))
    cmd = [exe, "simulate", "--pose", "goal", "--wrench", wrench, "--duration", f"{duration:g}", "--dt", f"{DT:g}"]
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def cli_simulate(quick: bool) -> tuple[list[dict], dict[str, Any]]:
    """`fixplan simulate` of the six-locator box, whole process, 22 s minus 2 s simulated at dt 1 ms.

    Runs are interleaved (short, long, MuJoCo rollout of the same 20000 steps) so that load from
    other processes hits all three alike. Two figures: the difference of the fastest long and
    the fastest short run, and the median of the paired differences.
    """
    fx = fixplan.load(fixplan.default_fixture_path())
    push = -PUSH_N * np.ones(3) / math.sqrt(3.0)
    wrench = ",".join(f"{x:.12g}" for x in [*push, 0.0, 0.0, 0.0])
    n = int(round((CLI_LONG_S - CLI_SHORT_S) / DT))
    reps = 5 if quick else 15
    _simulate_process(CLI_SHORT_S, wrench)  # numba cache and imports in the OS's file cache
    sc = None
    if mujoco is not None:
        sc = MjScene(fx, fx.goal, DT, push)
        sc.time_rollout(100)
    short, long, roll, short_cpu, long_cpu, roll_cpu = [], [], [], [], [], []
    for _ in range(reps):
        w, c = _simulate_process(CLI_SHORT_S, wrench)
        short.append(w)
        short_cpu.append(c)
        w, c = _simulate_process(CLI_LONG_S, wrench)
        long.append(w)
        long_cpu.append(c)
        if sc is not None:
            c0 = time.process_time()
            roll.append(sc.time_rollout(n)[0])
            roll_cpu.append(time.process_time() - c0)
    diff_min = min(long) - min(short)
    diff_med = statistics.median(b - a for a, b in zip(short, long, strict=True))
    diff_cpu = statistics.median(long_cpu) - statistics.median(short_cpu)
    diff_q1 = float(np.quantile(long, 0.25) - np.quantile(short, 0.25))
    info = {
        "short": short,
        "long": long,
        "fixplan_min": n / diff_min,
        "fixplan_median": n / diff_med,
        "fixplan_cpu": n / diff_cpu,
        "fixplan_q1": n / diff_q1,
        "mujoco_q1": n / float(np.quantile(roll, 0.25)) if roll else float("nan"),
        "mujoco": n / min(roll) if roll else float("nan"),
        "mujoco_median": n / statistics.median(roll) if roll else float("nan"),
        "mujoco_cpu": n / statistics.median(roll_cpu) if roll_cpu else float("nan"),
        "reps": reps,
        "wrench": wrench,
    }
    rows = [
        _row(
            "six-locator box, whole process",
            "fixplan",
            "`fixplan simulate` 22 s − 2 s (fastest of each)",
            tolerance=TOL,
            sim_time_s=n * DT,
            steps=n,
            wall_s_best=diff_min,
            note=f"median of paired differences {diff_med:.4f} s; CPU (user+system) medians: long − short "
            f"{diff_cpu:.4f} s; short runs {min(short):.2f}–{max(short):.2f} s",
        )
    ]
    if roll:
        rows.append(
            _row(
                "six-locator box, whole process",
                "MuJoCo",
                "mujoco.rollout (C++ loop), same steps, same minutes",
                sim_time_s=n * DT,
                steps=n,
                wall_s_best=min(roll),
            )
        )
    return rows, info


# ---------------------------------------------------------------------------------------------
# 2. incline stick, 3. incline slide
# ---------------------------------------------------------------------------------------------
def incline_stick(quick: bool, reps: int) -> list[dict]:
    fx = box_on_three("stick", 0.5, incline_gravity(20.0))
    T = 2.0
    n = int(round(T / DT))
    item = "incline stick 20°, μ 0.5"
    rows = []
    wall, (sim, _) = _best(reps, lambda: _fixplan_run(fx, fx.start, T, None, DT, TOL))
    _, (_, traj) = _fixplan_run(fx, fx.start, T, None, DT, TOL, every=1)
    p = np.array(traj.position)
    p0 = p[0]
    half = len(p) // 2
    rows.append(
        _row(
            item,
            "fixplan",
            "Simulator.run (compiled loop)",
            tolerance=TOL,
            sim_time_s=T,
            steps=n,
            wall_s_best=wall,
            creep_m=float(np.linalg.norm(p[-1, :2] - p0[:2])),
            creep_last_1s_m=float(np.linalg.norm(p[-1, :2] - p[half, :2])),
            normal_disp_m=float(np.max(np.abs(p[:, 2] - p0[2]))),
            penetration_max_m=max(sim.max_penetration_m, float(max(0.0, -np.min(traj.gap)))),
            mean_iterations=float(np.mean(traj.iterations[1:])),
            note="modes " + " ".join(c.mode for c in sim.contacts()),
        )
    )
    if mujoco is not None:
        sc = MjScene(fx, fx.start, DT, np.zeros(3))
        sc.time_rollout(10)
        wall_loop, _ = _best(reps, lambda: (sc.time_loop(n), None))
        wall_roll, states = _best(reps, lambda: sc.time_rollout(n))
        rec = sc.record(n)
        p = rec["p"]
        common = {
            "sim_time_s": T,
            "steps": n,
            "creep_m": float(np.linalg.norm(p[-1, :2] - p[0, :2])),
            "creep_last_1s_m": float(np.linalg.norm(p[-1, :2] - p[half, :2])),
            "normal_disp_m": float(np.max(np.abs(p[:, 2] - p[0, 2]))),
            "penetration_max_m": float(rec["pen"].max()),
        }
        rows.append(_row(item, "MuJoCo", "mj_step loop in Python", wall_s_best=wall_loop, **common))
        rows.append(_row(item, "MuJoCo", "mujoco.rollout (C++ loop)", wall_s_best=wall_roll, **common))
    return rows


def slide_closed_form() -> float:
    th = math.radians(30.0)
    return G * (math.sin(th) - 0.3 * math.cos(th))


def incline_slide(quick: bool, reps: int) -> list[dict]:
    fx = box_on_three("slide", 0.3, incline_gravity(30.0))
    a = slide_closed_form()
    T = 0.1
    n = int(round(T / DT))
    item = "incline slide 30°, μ 0.3"
    rows = []
    wall, _ = _best(reps, lambda: _fixplan_run(fx, fx.start, T, None, DT, TOL))
    _, (sim, traj) = _fixplan_run(fx, fx.start, T, None, DT, TOL, every=1)
    Rs = np.array([matrix_from_quaternion_wxyz(q) for q in traj.orientation])
    m = _slide_metrics(fx, np.array(traj.time_s), np.array(traj.position), Rs, np.array(traj.velocity)[:, 0], a)
    rows.append(
        _row(
            item,
            "fixplan",
            "Simulator.run (compiled loop)",
            tolerance=TOL,
            sim_time_s=T,
            steps=n,
            wall_s_best=wall,
            penetration_max_m=max(sim.max_penetration_m, float(max(0.0, -np.min(traj.gap)))),
            mean_iterations=float(np.mean(traj.iterations[1:])),
            **m,
            note="modes " + " ".join(c.mode for c in sim.contacts()),
        )
    )
    if mujoco is not None:
        sc = MjScene(fx, fx.start, DT, np.zeros(3))
        sc.time_rollout(10)
        wall_loop, _ = _best(reps, lambda: (sc.time_loop(n), None), budget_s=0.05)
        wall_roll, _ = _best(reps, lambda: sc.time_rollout(n), budget_s=0.05)
        rec = sc.record(n)
        Rs = np.array([matrix_from_quaternion_wxyz(q) for q in rec["quat"]])
        m = _slide_metrics(fx, rec["t"], rec["p"], Rs, rec["v"][:, 0], a)
        m["penetration_max_m"] = float(rec["pen"].max())
        rows.append(_row(item, "MuJoCo", "mj_step loop in Python", sim_time_s=T, steps=n, wall_s_best=wall_loop, **m))
        rows.append(
            _row(item, "MuJoCo", "mujoco.rollout (C++ loop)", sim_time_s=T, steps=n, wall_s_best=wall_roll, **m)
        )
    return rows


# ---------------------------------------------------------------------------------------------
# 4. speed against error
# ---------------------------------------------------------------------------------------------
DTS = (1e-2, 3e-3, 1e-3, 3e-4, 1e-4)
TOLS = (1e-4, 1e-6, 1e-8, 1e-10)


def sweep(quick: bool, reps: int) -> list[dict]:
    a = slide_closed_form()
    T = 0.1
    item = "sweep: incline slide, v at 0.1 s"
    rows = []
    budget = 0.1 if quick else 0.3
    for dt in DTS:
        fx = box_on_three("slide", 0.3, incline_gravity(30.0), dt=dt)
        n = int(round(T / dt))
        for tol in TOLS:
            wall, (sim, _) = _best(
                reps, lambda fx=fx, dt=dt, tol=tol: _fixplan_run(fx, fx.start, T, None, dt, tol), budget
            )
            t_end = sim.time_s
            err = abs(sim.twist[0] - a * t_end) / (a * t_end)
            _, (_, traj) = _fixplan_run(fx, fx.start, T, None, dt, tol, every=1)
            rows.append(
                _row(
                    item,
                    "fixplan",
                    "Simulator.run (compiled loop)",
                    dt_s=dt,
                    tolerance=tol,
                    sim_time_s=t_end,
                    steps=n,
                    wall_s_best=wall,
                    vel_rel_err=err,
                    mean_iterations=float(np.mean(traj.iterations[1:])),
                )
            )
        if mujoco is not None:
            sc = MjScene(fx, fx.start, dt, np.zeros(3))
            sc.time_rollout(2)
            wall_roll, states = _best(reps, lambda sc=sc, n=n: sc.time_rollout(n), budget)
            wall_loop, _ = _best(reps, lambda sc=sc, n=n: (sc.time_loop(n), None), budget)
            t_end, vx = float(states[-1, 0]), float(states[-1, 8])
            err = abs(vx - a * t_end) / (a * t_end)
            for method, w in (("mujoco.rollout (C++ loop)", wall_roll), ("mj_step loop in Python", wall_loop)):
                rows.append(
                    _row(item, "MuJoCo", method, dt_s=dt, sim_time_s=t_end, steps=n, wall_s_best=w, vel_rel_err=err)
                )
    return rows


def pareto(points: list[tuple[float, float]]) -> list[bool]:
    """Which (time, error) points no other point beats in both (≤ in both, < in one)."""
    out = []
    for i, (ti, ei) in enumerate(points):
        dominated = any((tj <= ti and ej <= ei) and (tj < ti or ej < ei) for j, (tj, ej) in enumerate(points) if j != i)
        out.append(not dominated)
    return out


# ---------------------------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------------------------
def _e(x: float, digits: int = 2) -> str:
    if x != x:
        return "–"
    return "0" if x == 0 else f"{x:.{digits}e}"


def _it(r: dict) -> str:
    x = r["mean_iterations"]
    return "–" if x != x else f"{x:.2f}"


def _ratio(mj: float, fp: float) -> str:
    if fp == 0.0:
        return "∞ (fixplan exactly 0)"
    return f"{mj / fp:.3g}×"


def run(quick: bool) -> Section:
    reps = 5 if quick else 9
    rows_box, info = six_locator_box(quick, reps)
    rows_cli, cli = cli_simulate(quick)
    rows_stick = incline_stick(quick, reps)
    rows_slide = incline_slide(quick, reps)
    rows_sweep = sweep(quick, reps)
    rows = rows_box + rows_cli + rows_stick + rows_slide + rows_sweep

    def pick(rs, engine, method_prefix):
        return next((r for r in rs if r["engine"] == engine and r["method"].startswith(method_prefix)), None)

    L: list[str] = []
    L += [
        "fixplan's Moreau–Jean/NSGS engine (`fixplan.engine.simulator.Simulator`) against MuJoCo on the same scenes, same dt and",
        "same initial states, in one process. Wall times are the best of "
        f"{reps} runs (2 cores shared with other work); steps/s = steps / best wall time.",
        f"fixplan runs use `Simulator.run(T, wrench, record_every={NEVER:.0e})` after a warm-up run "
        f"({info['warmup_s']:.2f} s, numba cache load); tolerance {TOL:g} for items 1–3.",
    ]
    if mujoco is not None:
        o = info["mj_opt"]
        integ = {0: "Euler", 1: "RK4", 2: "implicit", 3: "implicitfast"}.get(int(o.integrator), str(o.integrator))
        solver = {0: "PGS", 1: "CG", 2: "Newton"}.get(int(o.solver), str(o.solver))
        L += [
            f"MuJoCo {mujoco.__version__}: MJCF built in code (free box body, same size/mass/inertia; locators as fixed sphere",
            f"geoms: 5 mm tips for the default fixture, {MJ_POINT_RADIUS:g} m spheres touching the box for point locators),",
            f'`cone="elliptic"`, condim 3, friction μ on box and locators, integrator {integ}, solver {solver} '
            f"(iterations {o.iterations}, tolerance {o.tolerance:g}), impratio {o.impratio:g}, **default** "
            f"solref {tuple(float(x) for x in o.o_solref)} and solimp {tuple(float(x) for x in o.o_solimp)}, no margin, no noslip.",
            "The push is `qfrc_applied` on the free joint (a force at the centre of mass, no moment).",
            "`mj_step loop` calls `mujoco.mj_step` from Python; `mujoco.rollout` runs the same steps in C++ on the calling thread.",
        ]
    else:
        L.append("**MuJoCo is not installed: only fixplan's side is reported.**")

    # section 1
    L += [
        "",
        "### 1. Six-locator box: default fixture at its goal, 5 N along (−1,−1,−1)/√3 through the centre of mass, dt = 1 ms",
        "",
    ]
    L += [
        "| engine | method | steps | best wall [s] | steps/s | NSGS sweeps/step | steady penetration [m] | max penetration over run [m] |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows_box:
        L.append(
            f"| {r['engine']} | {r['method']} | {r['steps']} | {r['wall_s_best']:.4f} | {r['steps_per_s']:,.0f} | {_it(r)} | {_e(r['penetration_steady_m'])} | {_e(r['penetration_max_m'])} |"
        )
    L += [
        "",
        "Penetration: fixplan = deepest start-of-step gap below zero over a recorded run and its own `max_penetration_m`;",
        "MuJoCo = `-min(data.contact.dist)` (steady: after the run, re-forwarded; max: over every step).",
        "Normal loads at the end [N]: fixplan "
        + _loads(info["fixplan_loads"])
        + (("; MuJoCo " + _loads(info["mj_loads"])) if "mj_loads" in info else "")
        + ". The rigid problem is statically indeterminate (base friction μN = 0.25 × 22.5 N = 5.6 N can hold the 4.1 N"
        " lateral push alone): fixplan's NSGS, cold-started with the base locators first in file order, leaves S1/S2/E1"
        " almost unloaded; MuJoCo's compliant contacts seat the box against them.",
    ]

    L += [
        "",
        "### 1b. The same push through the command a user runs: `fixplan simulate`, whole process",
        "",
        f"`fixplan simulate --pose goal --wrench {cli['wrench']} --duration T --dt 0.001` for T = {CLI_LONG_S:g} s and "
        f"{CLI_SHORT_S:g} s, {cli['reps']} of each interleaved with a MuJoCo rollout of the same "
        f"{int(round((CLI_LONG_S - CLI_SHORT_S) / DT))} steps; steps/s = 20000 / (time of the long run − time of the short run): "
        "start-up (imports, numba cache load, fixture) cancels.",
        "",
        "| engine | method | steps | wall [s] | steps/s |",
        "|---|---|---:|---:|---:|",
    ]
    for r in rows_cli:
        L.append(f"| {r['engine']} | {r['method']} | {r['steps']} | {r['wall_s_best']:.4f} | {r['steps_per_s']:,.0f} |")
    L += [
        "",
        f"CPU time (user + system of the processes; MuJoCo: `time.process_time` around the rollout), medians: fixplan "
        f"**{cli['fixplan_cpu']:,.0f}** steps/s, MuJoCo **{cli['mujoco_cpu']:,.0f}** steps/s "
        f"(factor {cli['fixplan_cpu'] / cli['mujoco_cpu']:.2f}): the same difference, less sensitive to the other "
        "processes on the machine than wall time.",
        "",
        f"Lower quartiles (difference of the 25th percentiles of the long and short runs): fixplan "
        f"{cli['fixplan_q1']:,.0f} steps/s, MuJoCo {cli['mujoco_q1']:,.0f}. "
        f"Median of the paired differences: fixplan {cli['fixplan_median']:,.0f} steps/s (MuJoCo's median rollout "
        f"{cli['mujoco_median']:,.0f}). Short runs took {min(cli['short']):.2f}–{max(cli['short']):.2f} s, long runs "
        f"{min(cli['long']):.2f}–{max(cli['long']):.2f} s: the spread of the start-up on this shared machine is larger "
        "than the 20000 steps themselves, hence the repetitions.",
    ]

    # items 2, 3
    L += ["", "### 2. Incline stick (θ = 20°, μ = 0.5, three point locators, tilted gravity, 2 s, dt = 1 ms)", ""]
    L += [
        "| engine | method | best wall [s] | steps/s | NSGS sweeps/step | creep in 2 s [m] | creep in the last 1 s [m] | max normal displacement [m] |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows_stick:
        L.append(
            f"| {r['engine']} | {r['method']} | {r['wall_s_best']:.4f} | {r['steps_per_s']:,.0f} | {_it(r)} | {_e(r['creep_m'])} | {_e(r['creep_last_1s_m'])} | {_e(r['normal_disp_m'])} |"
        )
    L += [
        "",
        "Creep = in-plane displacement of the body origin; the normal displacement (sinking into MuJoCo's soft contacts) is separate.",
    ]
    a = slide_closed_form()
    L += [
        "",
        f"### 3. Incline slide (θ = 30°, μ = 0.3, 0.1 s, dt = 1 ms): closed form a = g (sin θ − μ cos θ) = {a:.6f} m/s²",
        "",
    ]
    L += [
        "| engine | method | best wall [s] | steps/s | NSGS sweeps/step | accel. rel. error (LSQ slope) | v(0.1 s) rel. error "
        "| max ‖v − a t‖ / (a·0.1) | lift-off: max normal displacement [m] | max rise [m] | max support gap [m] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows_slide:
        L.append(
            f"| {r['engine']} | {r['method']} | {r['wall_s_best']:.4f} | {r['steps_per_s']:,.0f} | {_it(r)} | {_e(r['accel_rel_err'])} | {_e(r['vel_rel_err'])} "
            f"| {_e(r['max_vel_dev_rel'])} | {_e(r['liftoff_m'])} | {_e(r['rise_m'])} | {_e(r['support_gap_m'])} |"
        )
    L += [
        "",
        "Lift-off = max |z − z₀| of the body origin over the run (normal displacement, either sign); rise = upward part only;",
        "support gap = largest gap between a support point and the box's bottom face (a support leaving the face).",
        "MuJoCo's box sinks into the soft contacts and chatters (contacts open and close while sliding), hence its lift-off;",
        "the run stops at 0.1 s because the trailing support unloads at ≈ 0.14 s (MuJoCo's box then tips: −0.4 mm at 0.2 s).",
    ]

    # section 4
    fp_sweep = [r for r in rows_sweep if r["engine"] == "fixplan"]
    front = pareto([(r["wall_s_per_sim_s"], r["vel_rel_err"]) for r in fp_sweep])
    for r, f in zip(fp_sweep, front, strict=True):
        r["note"] = "Pareto front" if f else ""
    allpts = [r for r in rows_sweep if r["engine"] == "fixplan" or r["method"].startswith("mujoco.rollout")]
    joint = pareto([(r["wall_s_per_sim_s"], r["vel_rel_err"]) for r in allpts])
    L += [
        "",
        "### 4. Speed against error: incline slide, relative velocity error at t ≈ 0.1 s vs wall time per simulated second",
        "",
    ]
    L += [
        "fixplan (rows: dt; columns: NSGS tolerance; cell: error / wall s per simulated s / mean NSGS sweeps per step; **bold** = on fixplan's Pareto front):",
        "",
    ]
    L += ["| dt [s] | " + " | ".join(f"tol {t:g}" for t in TOLS) + " |", "|---:|" + "---|" * len(TOLS)]
    for dt in DTS:
        cells = []
        for tol in TOLS:
            r = next(r for r in fp_sweep if r["dt_s"] == dt and r["tolerance"] == tol)
            c = f"{_e(r['vel_rel_err'], 1)} / {r['wall_s_per_sim_s']:.3g} s / {r['mean_iterations']:.1f}"
            cells.append(f"**{c}**" if r["note"] else c)
        L.append(f"| {dt:g} | " + " | ".join(cells) + " |")
    if mujoco is not None:
        L += ["", "MuJoCo (default solref/solimp; solref's time constant is clamped to ≥ 2 dt by MuJoCo):", ""]
        L += [
            "| dt [s] | v rel. error | rollout wall s / sim s | mj_step loop wall s / sim s | on the joint front |",
            "|---:|---:|---:|---:|---|",
        ]
        for dt in DTS:
            rr = next(
                r
                for r in rows_sweep
                if r["engine"] == "MuJoCo" and r["dt_s"] == dt and r["method"].startswith("mujoco.rollout")
            )
            rl = next(
                r
                for r in rows_sweep
                if r["engine"] == "MuJoCo" and r["dt_s"] == dt and r["method"].startswith("mj_step")
            )
            on = joint[allpts.index(rr)]
            L.append(
                f"| {dt:g} | {_e(rr['vel_rel_err'])} | {rr['wall_s_per_sim_s']:.3g} | {rl['wall_s_per_sim_s']:.3g} | {'yes' if on else 'no'} |"
            )
    fr = [f"dt {r['dt_s']:g}/tol {r['tolerance']:g}" for r in fp_sweep if r["note"]]
    L += ["", "fixplan settings on its Pareto front (time, error): " + ", ".join(fr) + "."]
    fj = [
        f"{r['engine']} dt {r['dt_s']:g}" + (f"/tol {r['tolerance']:g}" if r["engine"] == "fixplan" else "")
        for r, f in zip(allpts, joint, strict=True)
        if f
    ]
    L += ["Joint front (fixplan grid + MuJoCo rollout): " + ", ".join(fj) + "."]
    L += [
        "For a constant acceleration the Moreau–Jean step is exact in dt, so fixplan's error is set by the NSGS tolerance"
        " (and the warm start) alone and the largest dt dominates: per simulated second, smaller dt only costs more steps."
        " MuJoCo's error comes from the soft contact model and does not fall with dt."
    ]

    # targets
    L += ["", "### Targets", ""]
    fp1 = pick(rows_box, "fixplan", "Simulator.run")
    if mujoco is not None:
        roll1 = pick(rows_box, "MuJoCo", "mujoco.rollout")
        loop1 = pick(rows_box, "MuJoCo", "mj_step")
        fps, rs, ls = fp1["steps_per_s"], roll1["steps_per_s"], loop1["steps_per_s"]
        L.append(
            f"- steps/s ≥ MuJoCo's on the six-locator box (API): fixplan **{fps:,.0f}** vs MuJoCo rollout **{rs:,.0f}** "
            f"(factor {fps / rs:.2f}: {'met' if fps >= rs else 'missed'}) and vs the mj_step loop {ls:,.0f} "
            f"(factor {fps / ls:.2f}: {'met' if fps >= ls else 'missed'}). Measured before the speed work: 0.60×."
        )
        fc, mc = cli["fixplan_min"], cli["mujoco"]
        fcm, mcm = cli["fixplan_median"], cli["mujoco_median"]
        L.append(
            f"- the same through `fixplan simulate` (whole process, 22 s − 2 s): fixplan **{fc:,.0f}** vs MuJoCo rollout "
            f"**{mc:,.0f}** (factor {fc / mc:.2f}: {'met' if fc >= mc else 'missed'}); medians {fcm:,.0f} vs {mcm:,.0f} "
            f"(factor {fcm / mcm:.2f}); lower quartiles {cli['fixplan_q1']:,.0f} vs {cli['mujoco_q1']:,.0f} "
            f"(factor {cli['fixplan_q1'] / cli['mujoco_q1']:.2f}); CPU time **{cli['fixplan_cpu']:,.0f}** vs "
            f"**{cli['mujoco_cpu']:,.0f}** (factor {cli['fixplan_cpu'] / cli['mujoco_cpu']:.2f}: "
            f"{'met' if cli['fixplan_cpu'] >= cli['mujoco_cpu'] else 'missed'}). Measured before the speed work: 0.16–0.62×. The "
            "wall-time differences carry the start-up's spread (seconds on a shared machine) against 20000 steps "
            "that take about 0.1 s; the CPU time of the same processes is the steadier figure."
        )
        fsl, msl = pick(rows_slide, "fixplan", "Simulator"), pick(rows_slide, "MuJoCo", "mujoco.rollout")
        L.append(
            f"- sliding box (API): fixplan **{fsl['steps_per_s']:,.0f}** vs MuJoCo rollout "
            f"**{msl['steps_per_s']:,.0f}** steps/s (factor {fsl['steps_per_s'] / msl['steps_per_s']:.2f}: "
            f"{'met' if fsl['steps_per_s'] >= msl['steps_per_s'] else 'missed'}); measured before the speed work: ≈ 0.25×. fixplan's"
            " time is its whole `Simulator.run` call (Python set-up and recording included), MuJoCo's the rollout call alone."
        )
        fs, ms = pick(rows_stick, "fixplan", "Simulator"), pick(rows_stick, "MuJoCo", "mujoco.rollout")
        fl, ml = pick(rows_slide, "fixplan", "Simulator"), pick(rows_slide, "MuJoCo", "mujoco.rollout")
        checks = [
            ("creep in 2 s", fs["creep_m"], ms["creep_m"], "≈ 2 mm"),
            ("lift-off (max normal displacement, slide)", fl["liftoff_m"], ml["liftoff_m"], "≈ 0.6 mm"),
            ("penetration at 5 N (steady)", fp1["penetration_max_m"], roll1["penetration_steady_m"], "≈ 0.2 mm"),
        ]
        for what, fpv, mjv, ref in checks:
            ok = fpv == 0.0 or mjv / fpv >= 100.0
            L.append(
                f"- {what} ≥ 100× smaller than MuJoCo's: fixplan **{_e(fpv)} m** vs MuJoCo **{_e(mjv)} m**: "
                f"{_ratio(mjv, fpv)} ({'met' if ok else 'missed'}). expected for MuJoCo: {ref}."
            )
        L.append("  (fixplan's penetration here is its worst over the run, not only the steady value.)")
    return Section("Contact engine against MuJoCo", "\n".join(L), rows)
