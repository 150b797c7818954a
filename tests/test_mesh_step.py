"""STEP parts through the optional CAD extra (``pip install fixplan[cad]``: OpenCASCADE's ``cadquery-ocp``).

Without the extra (the default install), a STEP part is one line keyed ``workpiece.file`` that
says how to install it (exit 2). With it (the tests below skip, saying why, when ``OCP`` does not
import), STEP files written by OpenCASCADE itself are read: a box in millimetres is the primitive
box to 1e-12, the same box written in metres gives the same part (the file states its unit), an
L made by a boolean cut has the closed-form volume and two contacts in its concave corner, and a
cylinder's triangles stay within the stated chordal tolerance of the true surface.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from fixplan.errors import FixtureError
from fixplan.fixture import load
from fixplan.geometry import Box
from fixplan.geometry.step import step_available

HAS_OCP = step_available()
needs_ocp = pytest.mark.skipif(not HAS_OCP, reason="the CAD extra is not installed (pip install fixplan[cad])")
# a STEP file's first lines: enough to be one by name and suffix (the extra is asked for before parsing)
STEP_HEAD = b"ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION((''),'2;1');\nENDSEC;\nDATA;\nENDSEC;\nEND-ISO-10303-21;\n"


def fixture(folder: Path, file: str, extra: str = "", name: str = "part.toml") -> Path:
    path = folder / name
    path.write_text(
        'format = 1\n[scene]\nname = "step"\ndimension = 3\n[workpiece]\nshape = "mesh"\n'
        f'file = "{file}"\n{extra}mass = 1.0\n'
        '[[locator]]\nname = "A"\nposition = [0.0, 0.0, -0.2]\nfriction = 0.3\n'
    )
    return path


def test_without_the_extra_a_step_part_is_one_line_naming_the_install(tmp_path: Path, monkeypatch) -> None:
    (tmp_path / "part.step").write_bytes(STEP_HEAD)
    for name in ["OCP", *(m for m in sys.modules if m.startswith("OCP."))]:
        monkeypatch.setitem(sys.modules, name, None)  # as if not installed: `import OCP.x` raises ImportError
    with pytest.raises(FixtureError, match=r"pip install fixplan\[cad\]") as exc:
        load(fixture(tmp_path, "part.step"))
    assert exc.value.issues[0].key == "workpiece.file" and "\n" not in str(exc.value.issues[0].message)


@pytest.mark.skipif(HAS_OCP, reason="the CAD extra is installed here: the message without it is tested in-process")
def test_the_cli_without_the_extra_exits_2_in_one_line(tmp_path: Path) -> None:
    (tmp_path / "part.stp").write_bytes(STEP_HEAD)
    proc = run_cli("validate", str(fixture(tmp_path, "part.stp")), check_rc=2)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "workpiece.file" in lines[0] and "pip install fixplan[cad]" in lines[0]


def test_units_are_refused_for_step_and_tolerance_for_other_meshes(tmp_path: Path) -> None:
    (tmp_path / "part.step").write_bytes(STEP_HEAD)
    with pytest.raises(FixtureError, match="states its own unit") as exc:
        load(fixture(tmp_path, "part.step", 'units = "mm"\n'))
    assert exc.value.issues[0].key == "workpiece.units"
    with pytest.raises(FixtureError, match="only used for a STEP file") as exc:
        load(fixture(tmp_path, "part.stl", "tolerance = 1e-4\n"))
    assert exc.value.issues[0].key == "workpiece.tolerance"
    with pytest.raises(FixtureError, match="chordal tolerance") as exc:
        load(fixture(tmp_path, "part.step", "tolerance = 1.0\n"))
    assert exc.value.issues[0].key == "workpiece.tolerance"


# -- with the extra ---------------------------------------------------------------------------------
def write_step(shape, path: Path, unit: str = "MM") -> None:
    from OCP.Interface import Interface_Static
    from OCP.STEPControl import STEPControl_AsIs, STEPControl_Writer

    Interface_Static.SetCVal_s("write.step.unit", unit)
    writer = STEPControl_Writer()
    writer.Transfer(shape, STEPControl_AsIs)
    assert writer.Write(str(path)) == 1
    Interface_Static.SetCVal_s("write.step.unit", "MM")


@needs_ocp
def test_a_step_box_in_mm_or_m_is_the_primitive_box(tmp_path: Path, rng: np.random.Generator) -> None:
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    box = BRepPrimAPI_MakeBox(gp_Pnt(-100.0, -50.0, -25.0), 200.0, 100.0, 50.0).Shape()  # millimetres
    write_step(box, tmp_path / "box-mm.step")
    write_step(box, tmp_path / "box-m.stp", unit="M")
    primitive = Box((0.2, 0.1, 0.05))
    for file in ("box-mm.step", "box-m.stp"):
        fx = load(fixture(tmp_path, file, name=f"{file}.toml"))
        mesh = fx.workpiece.shape
        assert mesh.faces.shape[0] == 12
        assert mesh.volume_m3 == pytest.approx(0.2 * 0.1 * 0.05, rel=1e-12)
        assert any("tessellated the STEP part to a chordal tolerance of 0.0001 m" in n for n in mesh.notes)
        for p in rng.uniform(-0.15, 0.15, size=(50, 3)):
            got, want = mesh.project(p), primitive.project(p)
            assert got.distance == pytest.approx(want.distance, abs=1e-12)
            np.testing.assert_allclose(got.point_body, want.point_body, atol=1e-12)


@needs_ocp
def test_a_step_l_has_its_volume_and_two_contacts_in_its_corner(tmp_path: Path) -> None:
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Cut
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.gp import gp_Pnt

    block = BRepPrimAPI_MakeBox(100.0, 40.0, 60.0).Shape()
    cut = BRepPrimAPI_MakeBox(gp_Pnt(10.0, -1.0, 10.0), 100.0, 42.0, 60.0).Shape()
    write_step(BRepAlgoAPI_Cut(block, cut).Shape(), tmp_path / "l.step")
    mesh = load(fixture(tmp_path, "l.step")).workpiece.shape
    assert mesh.volume_m3 == pytest.approx(0.1 * 0.04 * 0.01 + 0.01 * 0.04 * 0.05, rel=1e-12)
    corner = mesh.contacts(np.array([0.013, 0.02, 0.013]))
    assert [round(c.distance, 12) for c in corner] == [0.003, 0.003]


@needs_ocp
@pytest.mark.parametrize("tolerance", [1e-4, 1e-5])
def test_a_step_cylinder_stays_within_the_chordal_tolerance(tmp_path: Path, tolerance: float) -> None:
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeCylinder

    r, h = 0.02, 0.05
    write_step(BRepPrimAPI_MakeCylinder(1e3 * r, 1e3 * h).Shape(), tmp_path / "cyl.step")
    mesh = load(fixture(tmp_path, "cyl.step", f"tolerance = {tolerance!r}\n")).workpiece.shape
    V, F = mesh.vertices, mesh.faces
    radial = np.linalg.norm(V[:, :2], axis=1)
    on_side = np.abs(radial - r) <= 1e-9
    assert np.all(on_side | (np.abs(V[:, 2]) <= 1e-12) | (np.abs(V[:, 2] - h) <= 1e-12))  # vertices on the surface
    side = np.all(on_side[F], axis=1) & (np.ptp(V[F][:, :, 2], axis=1) > 0.0)
    edges = np.concatenate([V[F[side]][:, [0, 1, 2]] + V[F[side]][:, [1, 2, 0]]]) / 2.0  # edge midpoints
    sag = r - np.linalg.norm(edges.reshape(-1, 3)[:, :2], axis=1)
    assert sag.max() <= tolerance * (1.0 + 1e-6) and sag.max() > 0.0
    assert np.pi * r * r * h * (1.0 - 2.0 * tolerance / r) <= mesh.volume_m3 < np.pi * r * r * h
