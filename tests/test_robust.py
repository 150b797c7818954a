"""``fixplan robust``: one nominal plan verified on perturbed worlds, locally and on a Dask cluster.

The Wilson interval is checked against hand-computed values, the perturbation against its
definition (friction bounds, resting contacts, locator noise scale), and the run against itself:
the same seed gives the same verdicts whatever runs it (threads, processes, a real scheduler with
two workers on loopback), ``--perturb-seed K`` replays sample K, and zero uncertainty is ``solve``.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS, ROOT, run_cli

from fixplan.fixture import load
from fixplan.locating import locator_gaps
from fixplan.robust import RobustSettings, draw_world, robust, verify_sample, wilson_interval

JAMS = PROBLEMS / "naive-order-jams.toml"  # rests on B1 alone; plan {B1} → {B1,B2} → all
# a large uncertainty under which some samples of naive-order-jams fail (seed 1: B1 lost, re-plan fails)
HARD = ["--mu-spread", "0.9", "--pose-sigma", "3e-3,4", "--force-noise", "0.5", "--latency-ms", "20"]
HARD_SAMPLES = 3


def fixplan(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, timeout=timeout, cwd=ROOT)


def strict_json(text: str):  # type: ignore[no-untyped-def]
    def bad(name: str) -> None:
        raise ValueError(f"non-standard JSON constant {name}")

    return json.loads(text, parse_constant=bad)


def without_wall_time(payload: dict) -> dict:
    return {k: v for k, v in payload.items() if k != "wall_time_s"}


# -- the Wilson interval ---------------------------------------------------------------------------
def test_wilson_interval_against_hand_computed_values():
    # k = 45, n = 50, z = 1.959964: p = 0.9, z²/n = 0.0768292, centre = (0.9 + 0.0384146) / 1.0768292 = 0.8714610,
    # half = 1.959964 / 1.0768292 · √(0.9·0.1/50 + 3.841459/10000) = 1.820125 · 0.0467348 = 0.0850632
    # (the roots of (p − 0.9)² = z² p (1 − p) / 50: the published 0.7864, 0.9565)
    lo, hi = wilson_interval(45, 50)
    assert lo == pytest.approx(0.786398, abs=2e-6)
    assert hi == pytest.approx(0.956524, abs=2e-6)
    # k = 0 of 10: centre = half = (3.841459/20) / 1.384146 = 0.138766 → [0, 0.277532]
    lo, hi = wilson_interval(0, 10)
    assert lo == pytest.approx(0.0, abs=1e-12)
    assert hi == pytest.approx(0.277532, abs=2e-6)
    # k = n: the mirror image
    lo, hi = wilson_interval(10, 10)
    assert (lo, hi) == pytest.approx((1 - 0.277532, 1.0), abs=2e-6)
    assert wilson_interval(0, 0) is None
    lo, hi = wilson_interval(1, 1)
    assert 0.0 < lo < 1.0 and hi == pytest.approx(1.0)


# -- the perturbed world ---------------------------------------------------------------------------
def test_perturbed_worlds_keep_the_resting_contacts_and_have_the_right_scale():
    fx = load(JAMS)
    s = RobustSettings()
    offsets = []
    for k in range(150):
        world, noise, what = draw_world(fx, k, s)
        assert noise.force_noise == 0.05 and noise.latency_s == pytest.approx(0.002)
        for nominal, loc in zip(fx.locators, world.locators, strict=True):
            assert nominal.friction * 0.8 - 1e-15 <= loc.friction <= nominal.friction * 1.2 + 1e-15
            offsets.append(loc.p_world - nominal.p_world)
        gaps = dict(
            zip(
                [loc.name for loc in world.locators],
                locator_gaps(world.workpiece, world.start, world.locators),
                strict=True,
            )
        )
        assert abs(gaps["B1"]) <= 1e-9  # rests on B1, as nominally
        assert gaps["S1"] > 1e-6 and gaps["B2"] > 1e-6  # touches nothing else, penetrates nothing
        # the goal is recomputed from the moved locators: every one touches there
        assert np.max(np.abs(locator_gaps(world.workpiece, world.goal, world.locators))) <= 1e-9
    offsets_m = np.array(offsets)  # (150 · 3, 2)
    assert np.std(offsets_m) == pytest.approx(1e-4, rel=0.08)
    assert abs(np.mean(offsets_m)) < 1e-5
    # friction spreads over the whole band, not only part of it
    u = np.array([draw_world(fx, k, s)[0].locators[0].friction / 0.15 - 1 for k in range(60)])
    assert u.min() < -0.15 and u.max() > 0.15


def test_start_pose_noise_has_the_requested_scale():
    fx = load(JAMS)
    s = RobustSettings(mu_spread=0.0, locator_sigma_m=0.0, pose_sigma_m=1e-3, pose_sigma_deg=1.0)
    turns = [math.degrees(draw_world(fx, k, s)[0].start.angle_rad - fx.start.angle_rad) for k in range(200)]
    assert np.std(turns) == pytest.approx(1.0, rel=0.15)


def test_the_same_sample_is_the_same_world():
    fx = load(JAMS)
    s = RobustSettings(seed=7)
    a, na, _ = draw_world(fx, 3, s)
    b, nb, _ = draw_world(fx, 3, s)
    assert na == nb
    assert all(
        x.friction == y.friction and np.array_equal(x.p_world, y.p_world)
        for x, y in zip(a.locators, b.locators, strict=True)
    )
    assert np.array_equal(a.start.p_world, b.start.p_world)
    c, _, _ = draw_world(fx, 3, RobustSettings(seed=8))
    assert c.locators[0].friction != a.locators[0].friction


def test_bad_settings_are_refused():
    from fixplan.errors import InputError

    with pytest.raises(InputError, match="RobustSettings.mu_spread"):
        RobustSettings(mu_spread=1.5).check()
    with pytest.raises(InputError, match="RobustSettings.locator_sigma_m"):
        RobustSettings(locator_sigma_m=-1e-4).check()


# -- verdicts --------------------------------------------------------------------------------------
def test_zero_uncertainty_verifies_exactly_like_solve(jams_plan):
    from fixplan.planner.solve import plan_steps

    fx = load(JAMS)
    nominal = jams_plan  # solve(fx)
    zero = RobustSettings(mu_spread=0, pose_sigma_m=0, pose_sigma_deg=0, locator_sigma_m=0, force_noise=0, latency_s=0)
    steps = plan_steps(nominal.transitions)
    v = verify_sample(fx, frozenset({"B1"}), steps, 0, zero)
    assert nominal.verification is not None
    assert v.passed == nominal.verification.passed
    assert v.reason == nominal.verification.reason
    assert v.observed_sequence == nominal.verification.observed_sequence
    assert v.duration_s == nominal.verification.duration_s


def test_same_seed_same_json_in_process():
    from fixplan.cluster import dask_client

    fx = load(PROBLEMS / "rect-3.toml")
    s = RobustSettings(samples=3, seed=5)
    with dask_client(processes=False, tasks=2) as client:  # threads: the same verdicts as processes
        a = robust(fx, s, client=client).to_json()
        b = robust(fx, s, client=client).to_json()
    assert without_wall_time(a) == without_wall_time(b)
    assert a["samples"] == 3 and a["succeeded"] + len(a["failures"]) == 3
    assert [o["seed"] for o in a["outcomes"]] == [0, 1, 2]


# -- the command line, locally and on a real scheduler ---------------------------------------------
@pytest.fixture(scope="module")
def local_run():
    proc = fixplan("robust", str(JAMS), "--samples", str(HARD_SAMPLES), *HARD, "--json")
    assert proc.returncode == 0, proc.stderr
    return strict_json(proc.stdout)


def test_robust_json_contract(local_run):
    out = local_run
    assert set(out) >= {"samples", "succeeded", "success_rate", "interval", "failures", "plan_status", "wall_time_s"}
    assert out["samples"] == HARD_SAMPLES
    assert out["success_rate"] == pytest.approx(out["succeeded"] / HARD_SAMPLES)
    lo, hi = out["interval"]
    assert (lo, hi) == pytest.approx(wilson_interval(out["succeeded"], HARD_SAMPLES))
    assert out["plan_status"] == "planned"  # the plan solve delivers: it loads in the nominal world
    for f in out["failures"]:
        assert set(f) >= {"seed", "transition", "cause", "reason"}
        assert f["cause"] in {"lost contact", "unplanned contact", "stall", "timeout", "diverged", "limits",
                              "final gap", "penetration", "replan failed", "executor", "error", "no located pose", "other"}  # fmt: skip


def test_perturb_seed_replays_a_sample(local_run):
    # seeds 0 and 1: under HARD, seed 1 fails (B1 lost, no re-plan) and seed 0 passes
    failures = {f["seed"]: f for f in local_run["failures"]}
    for outcome in local_run["outcomes"][:2]:
        k = outcome["seed"]
        proc = fixplan("solve", str(JAMS), "--perturb-seed", str(k), *HARD, "--json")
        assert proc.returncode == (0 if outcome["passed"] else 1), proc.stderr
        out = strict_json(proc.stdout)
        assert out["verification"]["passed"] is outcome["passed"]
        assert out["perturbation"]["sample"] == k
        assert out["perturbation"]["cause"] == outcome["cause"]
        assert out["perturbation"]["transition"] == outcome["transition"]
        if k in failures:
            assert out["verification"]["reason"] == failures[k]["reason"]
            assert out["status"] == "unverified" and failures[k]["cause"] in out["reason"]


def test_robust_text_output_names_the_replay_command(tmp_path):
    proc = fixplan("robust", str(PROBLEMS / "rect-3.toml"), "--samples", "2", "--seed", "3")
    assert proc.returncode == 0, proc.stderr
    assert "success rate" in proc.stdout and "95 % Wilson interval" in proc.stdout


def _wait_for_file(path: Path, timeout_s: float) -> None:
    t0 = time.monotonic()
    while not path.exists() or not path.read_text().strip():
        if time.monotonic() - t0 > timeout_s:
            raise TimeoutError(f"{path} not written within {timeout_s} s")
        time.sleep(0.2)


@pytest.fixture
def dask_cluster(tmp_path):
    """A real scheduler and two single-threaded workers on 127.0.0.1, stopped afterwards."""
    dask = Path(sys.executable).parent / "dask"
    if not dask.exists():
        pytest.skip("the dask command is not installed")
    info = tmp_path / "scheduler.json"
    procs: list[subprocess.Popen] = []
    common = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "cwd": tmp_path}
    try:
        procs.append(subprocess.Popen(
            [str(dask), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file", str(info)],
            **common,
        ))  # fmt: skip
        _wait_for_file(info, 30)
        address = json.loads(info.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen(
                [str(dask), "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                 "--no-dashboard", "--death-timeout", "30"],
                **common,
            ))  # fmt: skip
        from distributed import Client

        with Client(address, timeout="20s") as client:
            client.wait_for_workers(2, timeout=60)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in reversed(procs):
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=5)


def test_a_real_cluster_gives_the_same_verdicts(local_run, dask_cluster):
    proc = fixplan("robust", str(JAMS), "--samples", str(HARD_SAMPLES), *HARD, "--scheduler", dask_cluster, "--json")
    assert proc.returncode == 0, proc.stderr
    remote = strict_json(proc.stdout)
    assert without_wall_time(remote) == without_wall_time(local_run)


def test_unreachable_scheduler_exits_2_within_the_timeout():
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    proc = fixplan("robust", str(JAMS), "--scheduler", f"tcp://127.0.0.1:{port}", timeout=60)
    elapsed = time.monotonic() - t0
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"tcp://127.0.0.1:{port}" in lines[0], proc.stderr
    assert elapsed < 25  # 10 s to connect, plus starting Python


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["--mu-spread", "2"], "--mu-spread"),
        (["--pose-sigma", "1e-3"], "--pose-sigma"),
        (["--pose-sigma", "a,b"], "--pose-sigma"),
        (["--locator-sigma", "-1"], "--locator-sigma"),
        (["--latency-ms", "nan"], "--latency-ms"),
        (["--samples", "0"], "--samples"),
        (["--scheduler", "localhost"], "--scheduler"),
    ],
)
def test_bad_options_exit_2_with_one_line(args, match):
    proc = fixplan("robust", str(JAMS), *args)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and match in lines[0], proc.stderr
    assert proc.stdout == ""


def test_solve_batch(tmp_path):
    for name in ("rect-3.toml", "polygon-2d.toml"):
        (tmp_path / name).write_text((PROBLEMS / name).read_text())
    proc = fixplan("solve", "--batch", str(tmp_path), "--json")
    assert proc.returncode == 0, proc.stderr
    out = strict_json(proc.stdout)
    assert [Path(f["file"]).name for f in out["fixtures"]] == ["polygon-2d.toml", "rect-3.toml"]
    assert all(f["status"] == "planned" and f["verification"]["passed"] for f in out["fixtures"])
    (tmp_path / "broken.toml").write_text("format = 1\n")
    proc = fixplan("solve", "--batch", str(tmp_path), "--json")
    assert proc.returncode == 1
    rows = {Path(f["file"]).name: f for f in strict_json(proc.stdout)["fixtures"]}
    assert rows["broken.toml"]["status"] == "invalid" and "scene" in rows["broken.toml"]["reason"]
    assert fixplan("solve", "--batch", str(tmp_path / "nope")).returncode == 2


def test_a_world_where_the_part_slips_onto_a_wrong_face_is_recovered():
    # world 60 of the default fixture (default uncertainty): B2 starts 1.6 mm from the base's edge;
    # in the first transition the part slips off it and B2 ends up pressing the -y face. Before
    # the executor lifted such a part off and approached again, every re-plan failed ("B2 cannot
    # close while B2 stays touching its -y face") and the sample failed.
    from fixplan import default_fixture_path
    from fixplan.robust import nominal_plan

    fx = load(default_fixture_path())
    settings = RobustSettings()
    result, start_state, steps = nominal_plan(fx, settings)
    v = verify_sample(fx, start_state, steps, 60, settings, result.policy)
    events = [m for _, k, m in v.execution.events if k == "guard"]
    assert any("B2 presses face '-y'" in m and "lifting" in m for m in events), events
    assert v.passed, v.reason
    assert v.execution.counts["wrong_face"] >= 1
    assert max(v.final_gaps_m.values()) <= 1e-4
