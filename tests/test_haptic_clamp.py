"""``fixplan haptic --clamp``: the session plays the clamping stage once the part is located.

The loop runs headless (no device: the simulated hand), the part starting at its located pose.
Once located, each clamp ramps in the order ``fixplan clamp`` finds while the hand holds, the hand
lets go, each load ramps, holds and ramps down. Checked with numbers:

- the part stays put from the moment the hand lets go: displacement ≤ 1e-9 m, no counted contact
  opens beyond it (rigid contacts);
- the hand, let go, feels nothing (the device is shown 0);
- frictionless locators make every balance unique, so the engine's locator forces must equal the
  force program's: the default box with K3 = 30 + 1 N (the face-mill pull plus E1's preload),
  K1 = 30 − m g + 4 N (retract, the base at 1 N, 1 N, 2 N about the centred load) and
  K2 = 1 + 1/0.06 + 1 N (the drill's 1 N·m yaw taken by S1, S2 at ±0.06 m, S2 at its preload);
  with friction they differ (a rigid part with friction is statically indeterminate) and are reported.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import PROBLEMS

from fixplan.errors import InputError
from fixplan.fixture import load, loads
from fixplan.interactive.session import HapticSession

G = 9.81
BOX_CLAMPED = PROBLEMS / "box-3-2-1-clamped.toml"
HOUSING_CLAMPED = PROBLEMS / "housing-2-pins-clamped.toml"
FORCE_TOL_N = 1e-6  # the engine's NSGS residual (the fixture's 1e-8) on forces of tens of newtons


def _play(fixture):
    s = HapticSession(fixture, None, realtime=False, synchronous=True, until_goal=True, duration_s=5.0,
                      guidance=False, clamp=True)  # fmt: skip
    return s, s.run()


@pytest.mark.parametrize("path", [BOX_CLAMPED, HOUSING_CLAMPED], ids=lambda p: p.stem)
def test_the_session_plays_the_clamping_stage_and_the_part_stays_put(path) -> None:
    fixture = load(path)
    session, result = _play(fixture)
    assert result.reached, result.reason
    c = result.clamping
    assert c is not None and c["played"] and c["passed"], c
    assert c["max_displacement_m"] <= 1e-9 and c["max_gap_m"] <= 1e-9
    stage = session.clamp_stage
    assert stage is not None and c["steps"] == stage.n_ticks - stage.n_hand  # recorded from the release on
    assert set(c["loads"]) == {"clamped", *(ld.name for ld in fixture.loads)}
    assert result.duration_s == pytest.approx(c["located_at_s"] + stage.n_ticks * session.period_s, abs=1e-9)
    last = session.snapshot
    assert last is not None and np.all(last.felt_wrench == 0.0)  # the hand let go: nothing to feel
    assert set(c["locator_forces_N"]) == set(session.clamp_watched)


def test_frictionless_the_engine_forces_equal_the_force_programs() -> None:
    fixture = loads(BOX_CLAMPED.read_text().replace("friction = 0.25", "friction = 0.0"), source="box")
    session, result = _play(fixture)
    c = result.clamping
    assert c is not None and c["passed"], c
    forces = c["forces_N"]
    assert forces["K3"] == pytest.approx(31.0, abs=1e-6)
    assert forces["K1"] == pytest.approx(30.0 - 2.0 * G + 4.0, abs=1e-6)
    assert forces["K2"] == pytest.approx(2.0 + 1.0 / 0.06, abs=1e-6)
    for name, f in c["locator_forces_N"].items():
        assert f["engine_N"] == pytest.approx(f["program_N"], abs=FORCE_TOL_N), name
    # and the program's are the closed form: the base under m g + K1 at 1/4, 1/4, 1/2; E1 takes K3
    expected = {"B1": 8.5, "B2": 8.5, "B3": 17.0, "E1": 31.0}
    for name, value in expected.items():
        assert c["locator_forces_N"][name]["program_N"] == pytest.approx(value, abs=1e-6)


def test_clamp_without_clamps_is_bad_input() -> None:
    with pytest.raises(InputError, match=r"HapticSession.clamp: .* has no \[\[clamp\]\] entries"):
        HapticSession(load(PROBLEMS / "box-3-2-1.toml"), None, realtime=False, guidance=False, clamp=True)


@pytest.mark.parametrize("path", [BOX_CLAMPED, HOUSING_CLAMPED, PROBLEMS / "clamp-tall-2d.toml"], ids=lambda p: p.stem)
def test_the_simulated_haptic_loop_plays_the_stage_and_the_part_stays_put(path) -> None:
    """:class:`~fixplan.haptics.loop.HapticLoop` (the planner's verification rig) with the stage's clamps."""
    from fixplan.clamping import analyse_clamping
    from fixplan.clamping.forces import clamp_scene
    from fixplan.clamping.stage import ClampStage
    from fixplan.engine.simulator import Simulator
    from fixplan.haptics.clamping import play_clamping
    from fixplan.haptics.coordinates import coordinates_from_pose
    from fixplan.haptics.rig import haptic_rig
    from fixplan.settings import HAPTIC

    fixture = load(path)
    plan = analyse_clamping(fixture, verify=False)
    scene = clamp_scene(fixture)
    sim = Simulator(fixture, settings=HAPTIC.engine, tolerance=fixture.simulation.tolerance)
    sim.set_state(fixture.goal)
    x0 = coordinates_from_pose(fixture.goal, fixture.start.R_world_body)
    rig = haptic_rig(fixture, sim, x0, 40.0, 2.0)
    points = {c.name: c.point_world for c in scene.clamps}
    stage = ClampStage(fixture, plan.order, plan.forces_N, points, sim.dt)
    record, felt = play_clamping(rig.loop, stage, scene.owners)
    assert record.verdict()[0], record.verdict()[1]
    assert record.max_displacement_m <= 1e-9 and record.max_gap_m <= 1e-9
    assert felt == 0.0  # let go: the device shows nothing
    assert record.steps == stage.n_ticks - stage.n_hand


def test_cli_haptic_clamp_over_the_udp_bridge() -> None:
    """``fixplan haptic --clamp --clock device`` driven by ``device-sim --lockstep``: exit 0, strict JSON."""
    from test_interactive_cli import fixplan_cli, strict_json, udp_haptic

    code, stdout, stderr, _ = udp_haptic(
        [str(BOX_CLAMPED), "--until", "goal", "--clock", "device", "--clamp", "--json"],
        ["--lockstep", "--seed", "3", "--json"],
        device_timeout=180,
    )
    assert code == 0, stderr
    out = strict_json(stdout)
    c = out["clamping"]
    assert out["status"] == "reached" and c["played"] and c["passed"], c
    assert c["order"] == ["K1", "K2", "K3"] and c["max_displacement_m"] <= 1e-9
    r = fixplan_cli("haptic", str(PROBLEMS / "box-3-2-1.toml"), "--no-browser", "--clamp", "--until", "1")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "--clamp: " in r.stderr and "no [[clamp]] entries" in r.stderr
