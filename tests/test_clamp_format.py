"""``[[clamp]]`` and ``[[load]]`` in fixture files: read, checked against the located part, one-line errors.

The default box (fixplan/data/default.toml) is located with its centre at (0.1, 0.05, 0.025),
filling x in [0, 0.2], y in [0, 0.1], z in [0, 0.05]: a tip of radius 4 mm touching the top face
at its centre has its centre at z = 0.054.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import PROBLEMS, run_cli

from fixplan.errors import FixtureError
from fixplan.fixture import default_fixture_path, loads
from fixplan.twins import mirrored_fixture_text, rotated_fixture_text

BOX = default_fixture_path().read_text()
RECT = (PROBLEMS / "rect-3.toml").read_text()

TOP = """
[[clamp]]
name = "K1"
position = [0.1, 0.05, 0.054]
direction = [0.0, 0.0, -1.0]
radius = 0.004
friction = 0.3
max_force = 500.0
"""


def _with(text: str, extra: str):
    return loads(text + extra, source="f.toml")


def _issues(text: str) -> list[str]:
    with pytest.raises(FixtureError) as info:
        loads(text, source="f.toml")
    return [f"{i.key}: {i.message}" for i in info.value.issues]


def test_clamps_and_loads_are_read_with_unit_directions() -> None:
    fx = _with(
        BOX,
        TOP.replace("[0.0, 0.0, -1.0]", "[0.0, 0.0, -2.0]")
        + '\n[[load]]\nname = "mill"\nwrench = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]\n',
    )
    (k,) = fx.clamps
    assert k.name == "K1" and k.max_force_N == 500.0 and k.force_N is None and k.radius_m == 0.004
    assert np.allclose(k.direction_world, [0.0, 0.0, -1.0], atol=0.0)
    (ld,) = fx.loads
    assert ld.name == "mill" and np.array_equal(ld.wrench, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])


def test_a_fixture_without_clamps_is_unchanged() -> None:
    fx = loads(BOX, source="f.toml")
    assert fx.clamps == () and fx.loads == ()


@pytest.mark.parametrize(
    ("edit", "key", "words"),
    [
        (("0.054]", "0.064]"), "clamp.K1.position", "0.01 m away from the part"),
        (("0.054]", "0.050]"), "clamp.K1.position", "0.004 m inside the part"),
        (("max_force = 500.0", "max_force = 0.0"), "clamp.K1.max_force", "expected a force [N] > 0"),
        (("max_force = 500.0", "max_force = -3.0"), "clamp.K1.max_force", "expected a force [N] > 0"),
        (("max_force = 500.0", "max_force = 500.0\nforce = 600.0"), "clamp.K1.force", "above max_force"),
        (("[0.0, 0.0, -1.0]", "[0.0, 0.0, 0.0]"), "clamp.K1.direction", "zero vector"),
        (("[0.0, 0.0, -1.0]", "[0.0, -1.0]"), "clamp.K1.direction", "expected 3"),
        (("friction = 0.3", "friction = -0.3"), "clamp.K1.friction", "friction coefficient"),
        (("friction = 0.3\n", "friction = 0.3\nspeed = 3\n"), "clamp.K1.speed", "unknown key"),
        (('name = "K1"', 'name = "B1"'), "clamp.B1.name", "used twice"),
    ],
)
def test_bad_clamps_are_one_line_errors_naming_the_key(edit: tuple[str, str], key: str, words: str) -> None:
    issues = _issues(BOX + TOP.replace(*edit))
    assert any(i.startswith(key + ":") and words in i for i in issues), issues


def test_a_direction_out_of_the_surface_is_read_and_left_to_the_analysis() -> None:
    fx = _with(BOX, TOP.replace("[0.0, 0.0, -1.0]", "[0.0, 0.0, 1.0]"))
    assert fx.clamps[0].direction_world[2] == 1.0


@pytest.mark.parametrize(
    ("wrench", "words"),
    [("[1.0, 2.0, 3.0]", "expected 6 for a 3D scene: Fx, Fy, Fz, Tx, Ty, Tz"), ('"x"', "expected a list")],
)
def test_a_load_of_the_wrong_length_names_its_key(wrench: str, words: str) -> None:
    issues = _issues(BOX + f'\n[[load]]\nname = "L"\nwrench = {wrench}\n')
    assert any(i.startswith("load.L.wrench:") and words in i for i in issues), issues


def test_2d_clamps_and_loads() -> None:
    # rect-3: 0.2 x 0.1 located at centre (0.1, 0.05); the top face is y = 0.1
    clamp = (
        '\n[[clamp]]\nname = "K1"\nposition = [0.1, 0.1]\ndirection = [0.0, -1.0]\nfriction = 0.3\nmax_force = 50.0\n'
    )
    fx = _with(RECT, clamp + '\n[[load]]\nname = "L"\nwrench = [1.0, 0.0, 0.1]\n')
    assert fx.dimension == 2 and fx.clamps[0].p_world.shape == (2,) and fx.loads[0].wrench.shape == (3,)
    issues = _issues(RECT + clamp + '\n[[load]]\nname = "L"\nwrench = [1.0, 0.0, 0.0, 0.0, 0.0, 0.1]\n')
    assert any(i.startswith("load.L.wrench:") and "expected 3 for a 2D scene: Fx, Fy, Mz" in i for i in issues)


def test_clamps_need_a_full_fixture() -> None:
    one = RECT.split("[[locator]]")[0] + "[[locator]]" + RECT.split("[[locator]]")[1]
    clamp = (
        '\n[[clamp]]\nname = "K1"\nposition = [0.1, 0.1]\ndirection = [0.0, -1.0]\nfriction = 0.3\nmax_force = 50.0\n'
    )
    issues = _issues(one + clamp)
    assert any(i.startswith("clamp:") and "full fixture" in i for i in issues), issues


def test_validate_prints_one_line_and_exits_2(tmp_path: Path) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(BOX + TOP.replace("max_force = 500.0", "max_force = 100.0\nforce = 150.0"))
    proc = run_cli("validate", f, check_rc=2)
    assert proc.stderr.strip().splitlines() == [
        f"{f}: clamp.K1.force: got 150 N, above max_force = 100 N (expected a fixed force ≤ max_force)"
    ]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("turn", [math.pi / 3, -2.0])
def test_a_rotated_world_twin_moves_the_clamps_and_the_loads(turn: float) -> None:
    """The clamp stays on the part and the load turns with the world (its moment too)."""
    text = BOX + TOP + '\n[[load]]\nname = "L"\nwrench = [1.0, 2.0, 3.0, 0.1, 0.2, 0.3]\n'
    c, s = math.cos(turn), math.sin(turn)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    twin = loads(rotated_fixture_text(text, R), source="twin")  # validates: the tip is on the part
    assert np.allclose(twin.clamps[0].direction_world, R @ [0.0, 0.0, -1.0], atol=1e-12)
    assert np.allclose(twin.loads[0].wrench, np.concatenate([R @ [1.0, 2.0, 3.0], R @ [0.1, 0.2, 0.3]]), atol=1e-12)


def test_a_mirrored_twin_turns_the_load_moment_over() -> None:
    text = BOX + TOP + '\n[[load]]\nname = "L"\nwrench = [1.0, 2.0, 3.0, 0.1, 0.2, 0.3]\n'
    twin = loads(mirrored_fixture_text(text, [1.0, 0.0, 0.0], 0.0), source="twin")
    # x -> -x: a force (fx, fy, fz) -> (-fx, fy, fz); a moment (a pseudo-vector) -> (mx, -my, -mz)
    assert np.allclose(twin.loads[0].wrench, [-1.0, 2.0, 3.0, 0.1, -0.2, -0.3], atol=1e-12)
