"""The valid ranges of ``fixplan/limits.py``: refused outside with the key and the range, documented in docs/limits.md."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, run_cli

import fixplan
from fixplan import limits
from fixplan.errors import FixtureError

DOC = (ROOT / "docs" / "limits.md").read_text(encoding="utf-8")


def fixplan_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, timeout=300, cwd=cwd)


BOX = (ROOT / "problems" / "box-3-2-1.toml").read_text(encoding="utf-8")


@pytest.mark.parametrize(
    "rng",
    [v for v in vars(limits).values() if isinstance(v, limits.Range) and v is not limits.NORMAL],
    ids=lambda r: r.what,
)
def test_every_range_is_documented(rng: limits.Range) -> None:
    """docs/limits.md lists each range with the numbers the code uses (as the messages print them)."""
    row = f"{rng.low:g} to {rng.high:g}"
    assert row in DOC, f"docs/limits.md does not list {rng.expected()} ({row!r})"


def test_caps_are_documented() -> None:
    assert f"{limits.MAX_FILE_BYTES} bytes" in DOC
    assert f"| {limits.MAX_ENTRIES} |" in DOC
    assert f"{limits.MAX_SIM_STEPS:.0e}".replace("e+0", "e+0") in DOC
    assert f"1 to {limits.MAX_NAME_LENGTH} letters" in DOC


# (what to replace in box-3-2-1.toml, by what, the key, the range the message must quote)
OUTSIDE = [
    ("mass = 2.0", "mass = 1e-300", "workpiece.mass", "a mass [kg] in [1e-06, 10000]"),
    ("mass = 2.0", "mass = 1" + "0" * 400, "workpiece.mass", "an integer of 401 digits, too large for a float"),
    ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, 1e300]", "scene.gravity[2]", "in [-100, 100]"),
    ("size = [0.20, 0.10, 0.05]", "size = [200.0, 100.0, 50.0]", "workpiece.size[0]", "a length [m] in [0.0001, 100]"),
    ('friction = 0.25\nface = "-z"', 'friction = 1e300\nface = "-z"', "locator.B1.friction", "in [0, 10]"),
    (
        "position = [0.04, 0.02, 0.0]",
        "position = [1e300, 0.02, 0.0]",
        "locator.B1.position[0]",
        "a coordinate [m] in [-1000, 1000]",
    ),
    (
        'radius = 0.0\nfriction = 0.25\nface = "-z"',
        'radius = 0.0\nfriction = 0.25\ntorsion = 1e-300\nface = "-z"',
        None,
        None,
    ),
    ("max_force = 40.0", "max_force = 1e300", "manipulator.max_force", "a force [N] in [1e-06, 1e+06]"),
    (
        "rpy_deg = [0.0, 0.0, 0.0]",
        "rpy_deg = [0.0, 0.0, 1e300]",
        "workpiece.start.rpy_deg[2]",
        "an angle [deg] in [-360, 360]",
    ),
]


@pytest.mark.parametrize(("old", "new", "key", "expected"), OUTSIDE, ids=[c[1][:30] for c in OUTSIDE])
def test_outside_a_range_is_refused_with_key_and_range(tmp_path: Path, old, new, key, expected) -> None:
    assert old in BOX
    path = tmp_path / "f.toml"
    path.write_text(BOX.replace(old, new, 1))
    before = path.read_bytes()
    proc = fixplan_cli("validate", str(path))
    if key is None:  # torsion 1e-300 m is inside [0, 1]: a tiny soft finger, valid
        assert proc.returncode == 0, proc.stderr
        return
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert proc.stderr.splitlines() == [line for line in proc.stderr.splitlines() if line.startswith(f"{path}: ")]
    assert any(line.startswith(f"{path}: {key}: ") and expected in line for line in proc.stderr.splitlines()), (
        proc.stderr
    )
    assert "Traceback" not in proc.stderr and path.read_bytes() == before


def test_a_5000_digit_integer_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    path.write_text(BOX.replace("mass = 2.0", "mass = 1" + "0" * 5000))
    proc = fixplan_cli("classify", str(path), "--wrench", "0,0,0,0,0,0")
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        f"{path}: <toml>: invalid TOML: an integer of more than {sys.get_int_max_str_digits()} digits "
        "(expected numbers of ordinary size)"
    )


def test_inertia_beyond_any_rigid_body_is_refused() -> None:
    text = BOX.replace("mass = 2.0", "mass = 2.0\ninertia = [1.0, 1.0, 1.0]")
    with pytest.raises(
        FixtureError, match=r"workpiece.inertia: Ixx = 1 kg·m² is impossible .* \[2\.08e-06, 0\.0263\] kg·m²"
    ):
        fixplan.loads(text, "f.toml")
    # uniform Ixx = m (b² + c²) / 12 = 2 (0.01 + 0.0025) / 12 = 0.00208, of which 10⁻³ is the least;
    # m R² for the 0.2 x 0.1 x 0.05 box: R² = 0.1² + 0.05² + 0.025² = 0.013125, times 2 kg = 0.02625
    ok = BOX.replace("mass = 2.0", "mass = 2.0\ninertia = [0.002, 0.007, 0.008]")
    assert fixplan.loads(ok, "f.toml").workpiece.inertia_body[2, 2] == 0.008


def test_contact_normal_of_1e300_is_normalised() -> None:
    text = BOX + '\n[[contact]]\nname = "C"\npoint = [0.0, 0.0, 0.0]\nnormal = [1e300, 1e300, 0.0]\nfriction = 0.2\n'
    fx = fixplan.loads(text, "f.toml")
    assert np.allclose(fx.contacts[0].normal_world, [math.sqrt(0.5), math.sqrt(0.5), 0.0], atol=1e-15)


EDGES = [  # inside the ranges, at their edges: the commands give finite numbers or say why not
    ("mass = 2.0", "mass = 1e-6"),
    ("mass = 2.0", "mass = 1e4"),
    ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -100.0]"),
    ("gravity = [0.0, 0.0, -9.81]", "gravity = [100.0, 100.0, -100.0]"),
]


@pytest.mark.parametrize(("old", "new"), EDGES, ids=[e[1] for e in EDGES])
@pytest.mark.parametrize("wrench", ["1e6,0,0,0,0,0", "0,0,0,0,0,-1e6", "1e-9,0,0,0,0,0"])
def test_classify_at_the_edges_is_finite(tmp_path: Path, capsys, old: str, new: str, wrench: str) -> None:
    from fixplan.cli import main

    path = tmp_path / "f.toml"
    path.write_text(BOX.replace(old, new))
    code = main(["classify", str(path), "--wrench", wrench, "--json"])
    out, err = capsys.readouterr()
    assert code in (0, 2), err
    assert "internal error" not in err and "Traceback" not in err
    if code == 0:
        assert err == ""  # no numpy RuntimeWarning lines, no warnings: every locator touches
        result = json.loads(out, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))["results"][0]
        assert result["mode"] in ("held", "jammed", "separates", "slides", "pivots", "rolls", "indeterminate")
        if wrench == "1e6,0,0,0,0,0":  # 10⁶ N sideways beats any friction on the base: the box moves
            assert result["mode"] in ("slides", "separates", "pivots")
    else:  # the command says why not, in one line
        assert len(err.strip().splitlines()) == 1, err
