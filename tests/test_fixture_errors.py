"""Malformed fixture files: each gets its exact message, exit status 2, one line, no traceback."""

import subprocess
import sys
import textwrap

import pytest

import fixplan
from fixplan.errors import FixtureError

GOOD = textwrap.dedent(
    """
    format = 1
    [scene]
    name = "t"
    dimension = 3
    [workpiece]
    shape = "box"
    size = [0.2, 0.1, 0.05]
    mass = 2.0
    start = { position = [0.1, 0.05, 0.025], rpy_deg = [0.0, 0.0, 0.0] }
    [[locator]]
    name = "B1"
    position = [0.05, 0.03, -0.001]
    radius = 0.001
    friction = 0.3
    """
)

CASES = [
    ("missing-format", GOOD.replace("format = 1\n", ""), "format", "missing (expected 1)"),
    ("bad-format", GOOD.replace("format = 1", "format = 2"), "format", "got the number 2 (expected 1)"),
    ("unknown-key", GOOD.replace('name = "t"', 'name = "t"\ncolour = "red"'), "scene.colour", "unknown key"),
    ("negative-mass", GOOD.replace("mass = 2.0", "mass = -1.0"), "workpiece.mass", "expected a mass [kg] > 0"),
    (
        "wrong-length",
        GOOD.replace("size = [0.2, 0.1, 0.05]", "size = [0.2, 0.1]"),
        "workpiece.size",
        "got 2 numbers (expected 3 for a 3D scene)",
    ),
    (
        "string-number",
        GOOD.replace("friction = 0.3", 'friction = "high"'),
        "locator.B1.friction",
        "got the string 'high' (expected a friction coefficient)",
    ),
    (
        "negative-friction",
        GOOD.replace("friction = 0.3", "friction = -0.1"),
        "locator.B1.friction",
        "expected a friction coefficient ≥ 0",
    ),
    ("nan", GOOD.replace("mass = 2.0", "mass = nan"), "workpiece.mass", "expected a finite number"),
    (
        "negative-radius",
        GOOD.replace("radius = 0.001", "radius = -0.001"),
        "locator.B1.radius",
        "expected a tip radius [m] ≥ 0",
    ),
    (
        "bad-inertia",
        GOOD.replace("mass = 2.0", "mass = 2.0\ninertia = [1.0, 1.0, 3.0]"),
        "workpiece.inertia",
        "triangle inequality",
    ),
    (
        "nonpositive-inertia",
        GOOD.replace("mass = 2.0", "mass = 2.0\ninertia = [1.0, 0.0, 1.0]"),
        "workpiece.inertia",
        "positive-definite",
    ),
    (
        "twin-locators",
        GOOD + '[[locator]]\nname = "B2"\nposition = [0.05, 0.03, -0.001]\nradius = 0.001\nfriction = 0.3\n',
        "locator.B2.position",
        "at one place",
    ),
    (
        "inside",
        GOOD.replace("position = [0.05, 0.03, -0.001]", "position = [0.05, 0.03, 0.01]"),
        "locator.B1.position",
        "inside the workpiece",
    ),
    (
        "2d-with-3d-vector",
        GOOD.replace("dimension = 3", "dimension = 2")
        .replace('shape = "box"', 'shape = "rectangle"')
        .replace("size = [0.2, 0.1, 0.05]", "size = [0.2, 0.1]")
        .replace("rpy_deg = [0.0, 0.0, 0.0]", "angle_deg = 0.0"),
        "workpiece.start.position",
        "got 3 numbers (expected 2 for a 2D scene)",
    ),
    ("shape-of-other-dimension", GOOD.replace('shape = "box"', 'shape = "disk"'), "workpiece.shape", "a 2D shape"),
    (
        "mesh-missing-file",
        GOOD.replace('shape = "box"\nsize = [0.2, 0.1, 0.05]', 'shape = "mesh"\nfile = "part.stl"'),
        "workpiece.file",
        "'part.stl': cannot read: no such file",
    ),
    (
        "duplicate-name",
        GOOD + '[[locator]]\nname = "B1"\nposition = [0.15, 0.03, -0.001]\nradius = 0.001\nfriction = 0.3\n',
        "locator.B1.name",  # entries are addressed by name whenever they have a valid one
        "used twice",
    ),
    ("bad-toml", GOOD.replace("mass = 2.0", "mass = = 2.0"), "<toml>", "invalid TOML"),
    (
        "zero-normal",
        GOOD + '[[contact]]\nname = "c"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 0.0, 0.0]\nfriction = 0.2\n',
        "contact.c.normal",
        "zero vector",
    ),
    (
        "torsion-in-2d",
        GOOD.replace("dimension = 3", "dimension = 2")
        .replace('shape = "box"', 'shape = "rectangle"')
        .replace("size = [0.2, 0.1, 0.05]", "size = [0.2, 0.1]")
        .replace("position = [0.1, 0.05, 0.025], rpy_deg = [0.0, 0.0, 0.0]", "position = [0.1, 0.05], angle_deg = 0.0")
        .replace("position = [0.05, 0.03, -0.001]", "position = [0.05, -0.001]")
        .replace("friction = 0.3", "friction = 0.3\ntorsion = 0.01"),
        "locator.B1.torsion",
        "3D only",
    ),
]


@pytest.mark.parametrize(("name", "text", "key", "message"), CASES, ids=[c[0] for c in CASES])
def test_malformed_file_message(name, text, key, message, tmp_path):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    with pytest.raises(FixtureError) as info:
        fixplan.load(path)
    lines = str(info.value).splitlines()
    assert any(line.startswith(f"{path}: {key}: ") and message in line for line in lines), lines


def test_good_file_loads(tmp_path):
    path = tmp_path / "good.toml"
    path.write_text(GOOD)
    f = fixplan.load(path)
    assert f.dimension == 3 and len(f.locators) == 1 and not f.is_full


def test_validate_cli_one_line_per_error_exit_2(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(GOOD.replace("mass = 2.0", "mass = -1.0").replace("friction = 0.3", "friction = -2"))
    proc = subprocess.run([sys.executable, "-m", "fixplan.cli", "validate", str(path)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 2
    assert all(line.startswith(f"{path}: ") for line in lines)


@pytest.mark.parametrize(
    "args",
    [
        ["classify", "--wrench", "1,2"],
        ["classify", "--wrench", "a,b,c,d,e,f"],
        ["classify", "--wrench", "1,0,0,0,0,0", "--contacts", "NOPE"],
        ["classify", "--nonsense"],
        ["search", "--motion", "0,0,0,0,0,0"],
        ["map", "--axes", "Fx,Fx"],
        ["classify", "/does/not/exist.toml", "--wrench", "1,0,0,0,0,0"],
    ],
)
def test_cli_bad_input_is_one_line_and_exit_2(args):
    proc = subprocess.run([sys.executable, "-m", "fixplan.cli", *args], capture_output=True, text=True)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def _issues(tmp_path, text: str) -> list[str]:
    path = tmp_path / "f.toml"
    path.write_text(text)
    with pytest.raises(FixtureError) as info:
        fixplan.load(path)
    return [line.removeprefix(f"{path}: ") for line in str(info.value).splitlines()]


def test_every_bad_element_of_a_vector_is_reported(tmp_path):
    # a size in millimetres once reported only size[0]
    lines = _issues(tmp_path, GOOD.replace("size = [0.2, 0.1, 0.05]", 'size = [300, 200, "x"]'))
    assert [line.split(":")[0] for line in lines] == ["workpiece.size[0]", "workpiece.size[1]", "workpiece.size[2]"]
    assert "got 300" in lines[0] and "got 200" in lines[1] and "got the string 'x'" in lines[2]
    # the units hint is given once, on the first element too large
    assert sum("did you write millimetres?" in line for line in lines) == 1
    assert "sizes are in metres; did you write millimetres?" in lines[0]


@pytest.mark.parametrize(
    ("text", "key"),
    [
        (GOOD.replace('shape = "box"\nsize = [0.2, 0.1, 0.05]', 'shape = "sphere"\nradius = 250'), "workpiece.radius"),
        (GOOD.replace('shape = "box"\nsize = [0.2, 0.1, 0.05]', 'shape = "cylinder"\nradius = 0.02\nlength = 150'),
         "workpiece.length"),
    ],
)  # fmt: skip
def test_a_length_in_millimetres_gets_the_units_hint(tmp_path, text, key):
    lines = _issues(tmp_path, text)
    assert any(line.startswith(f"{key}: ") and "did you write millimetres?" in line for line in lines), lines


@pytest.mark.parametrize(("size", "unit"), [("20, 10, 5", "centimetres"), ("200, 100, 50", "millimetres")])
def test_sizes_in_cm_or_mm_with_the_rest_in_metres_get_the_units_hint(tmp_path, size, unit):
    # the tips are inside the part by metres; read in cm (or mm), the same sizes clear every tip.
    # 200 mm is above the length range: that element gets the hint instead (GOOD's 0.2 m edge)
    lines = _issues(tmp_path, GOOD.replace("size = [0.2, 0.1, 0.05]", f"size = [{size}]"))
    assert sum("did you write" in line for line in lines) == 1
    hinted = next(line for line in lines if "did you write" in line)
    assert f"sizes are in metres; did you write {unit}?" in hinted
    if unit == "centimetres":
        assert hinted.startswith("workpiece: the locators are inside the part")
        assert any("inside the workpiece" in line for line in lines)
    else:
        assert hinted.startswith("workpiece.size[0]: got 200")


def test_a_part_in_mm_within_the_length_range_gets_the_units_hint(tmp_path):
    # a 60 x 40 x 20 mm part: every edge is a valid length in metres, the tips are inside it
    text = (
        GOOD.replace("size = [0.2, 0.1, 0.05]", "size = [60, 40, 20]")
        .replace("position = [0.1, 0.05, 0.025]", "position = [0.03, 0.02, 0.01]")
        .replace("position = [0.05, 0.03, -0.001]", "position = [0.03, 0.02, -0.001]")
    )
    lines = _issues(tmp_path, text)
    assert lines[0] == (
        "workpiece: the locators are inside the part, and would not be were its sizes in millimetres: "
        "sizes are in metres; did you write millimetres?"
    )


def test_a_small_penetration_gets_no_units_hint(tmp_path):
    lines = _issues(tmp_path, GOOD.replace("position = [0.05, 0.03, -0.001]", "position = [0.05, 0.03, 0.01]"))
    assert not any("did you write" in line for line in lines)
