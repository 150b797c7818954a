"""A STEP part tessellated by OpenCASCADE (the optional CAD extra, ``pip install fixplan[cad]``).

``[workpiece] file = "part.step"`` (or ``.stp``): the file's B-rep is read by OpenCASCADE
(``cadquery-ocp``: a 64 MB wheel, about 1.3 GB installed with the VTK it pulls in, half a
minute to install here, so it is not a default dependency), every face is triangulated by
``BRepMesh_IncrementalMesh`` to the chordal tolerance ``workpiece.tolerance`` (the largest
distance between a triangle and the surface it stands for, in metres; default
``MeshSettings.step_tolerance_m``), and the triangles then go through every check of a mesh file
(:func:`fixplan.geometry.mesh.mesh_from_triangles`). The part is the tessellation: its gaps are
exact on the triangles, which lie within the tolerance of the CAD surface (flat faces exactly).

Units: a STEP file states its own length unit; OpenCASCADE converts it to millimetres (its
default session unit), and the vertices are taken from millimetres to metres. ``workpiece.units``
is therefore refused for a STEP file. Faces are wound by their B-rep orientation (a reversed face's
triangles are turned), so a closed solid comes out facing outwards. Without the extra, one line
says how to install it.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from fixplan.geometry.mesh import IntArray, MeshError
from fixplan.geometry.shapes import FloatArray

STEP_SUFFIXES = (".step", ".stp")
OCC_UNIT_M = 1e-3  # OpenCASCADE's session length unit (millimetres) in metres
INSTALL_HINT = "pip install fixplan[cad]"


def _occ() -> dict[str, Any]:
    """OpenCASCADE's classes, or :class:`MeshError` saying how to install them."""
    try:
        from OCP.BRep import BRep_Tool
        from OCP.BRepMesh import BRepMesh_IncrementalMesh
        from OCP.IFSelect import IFSelect_RetDone
        from OCP.STEPControl import STEPControl_Reader
        from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
        from OCP.TopExp import TopExp_Explorer
        from OCP.TopLoc import TopLoc_Location
        from OCP.TopoDS import TopoDS
    except ImportError:
        raise MeshError(
            "is a STEP file: reading STEP needs the optional CAD extra (OpenCASCADE), which is not installed: "
            f"{INSTALL_HINT} (or export the part as STL, OBJ or PLY)"
        ) from None
    return {
        "as_face": getattr(TopoDS, "Face_s", None) or TopoDS.Face,  # OCP 7.x names static methods with _s
        "BRep_Tool": BRep_Tool,
        "BRepMesh_IncrementalMesh": BRepMesh_IncrementalMesh,
        "IFSelect_RetDone": IFSelect_RetDone,
        "STEPControl_Reader": STEPControl_Reader,
        "TopAbs_FACE": TopAbs_FACE,
        "TopAbs_REVERSED": TopAbs_REVERSED,
        "TopExp_Explorer": TopExp_Explorer,
        "TopLoc_Location": TopLoc_Location,
    }


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """OpenCASCADE's own messages are dropped while it runs.

    It writes parse errors and statistics to the process's stdout and stderr, in colour: a bad
    file is one line of fixplan's, never a screenful of OpenCASCADE's.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    sink = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(sink, 1)
        os.dup2(sink, 2)
        yield
    finally:
        os.close(sink)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)


def step_available() -> bool:
    """Whether the CAD extra (OpenCASCADE's ``OCP``) imports."""
    try:
        _occ()
    except MeshError:
        return False
    return True


def step_triangles(path: Path, tolerance_m: float, angular_rad: float) -> tuple[FloatArray, IntArray]:
    """``(vertices (n, 3) [m], faces (m, 3))`` of the STEP file at ``path``, tessellated to ``tolerance_m``.

    OpenCASCADE's reader takes a path: :func:`fixplan.mesh_file.load_mesh_file` reads the user's
    file under the size limits and hands over a private copy of those bytes.

    ``angular_rad`` bounds the angle between neighbouring triangles' normals on a curved face
    (OpenCASCADE's angular deflection) as well.

    Raises
    ------
    MeshError
        The extra is not installed (one line naming ``pip install fixplan[cad]``), the bytes are
        not a STEP file with a shape, or a face could not be triangulated.
    """
    occ = _occ()
    with _quiet():
        reader = occ["STEPControl_Reader"]()
        readable = reader.ReadFile(str(path)) == occ["IFSelect_RetDone"]
        transferred = readable and reader.TransferRoots() > 0
        shape = reader.OneShape() if transferred else None
        if shape is not None and not shape.IsNull():
            occ["BRepMesh_IncrementalMesh"](shape, tolerance_m / OCC_UNIT_M, False, angular_rad, False)
    if not readable:
        raise MeshError("is not a readable STEP file (OpenCASCADE could not parse it)")
    if shape is None or shape.IsNull():
        raise MeshError("holds no shape OpenCASCADE can transfer (expected a solid part)")
    points: list[FloatArray] = []
    triangles: list[IntArray] = []
    offset = 0
    explorer = occ["TopExp_Explorer"](shape, occ["TopAbs_FACE"])
    while explorer.More():
        face = occ["as_face"](explorer.Current())
        location = occ["TopLoc_Location"]()
        mesh = occ["BRep_Tool"].Triangulation_s(face, location)
        if mesh is None:
            raise MeshError("has a face OpenCASCADE could not triangulate (expected a valid solid)")
        transform = location.Transformation()
        nodes = np.array(
            [mesh.Node(i).Transformed(transform).Coord() for i in range(1, mesh.NbNodes() + 1)], dtype=float
        ).reshape(-1, 3)
        tri = np.array([mesh.Triangle(i).Get() for i in range(1, mesh.NbTriangles() + 1)], dtype=np.int64)
        tri = tri.reshape(-1, 3) - 1 + offset
        if face.Orientation() == occ["TopAbs_REVERSED"]:
            tri = tri[:, ::-1]
        points.append(nodes)
        triangles.append(tri)
        offset += nodes.shape[0]
        explorer.Next()
    if not triangles:
        raise MeshError("has no faces (expected a solid part)")
    return np.concatenate(points) * OCC_UNIT_M, np.concatenate(triangles)


def tessellation_note(tolerance_m: float, angular_rad: float, triangles: int) -> str:
    """What reading a STEP file did, for ``validate --verbose``."""
    return (
        f"tessellated the STEP part to a chordal tolerance of {tolerance_m:g} m "
        f"(angular {math.degrees(angular_rad):g} deg): {triangles} triangles"
    )


__all__ = ["INSTALL_HINT", "STEP_SUFFIXES", "step_available", "step_triangles", "tessellation_note"]
