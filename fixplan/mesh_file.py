"""A fixture's mesh file (``[workpiece] shape = "mesh"``): where it may be, how much is read, then the mesh.

The file is read as :mod:`fixplan.files` reads every input: a regular file only (a directory, a
named pipe or a device is refused, and opening never blocks), at most
:data:`~fixplan.limits.MAX_MESH_BYTES`; a binary STL's triangle count is checked against
:data:`~fixplan.limits.MAX_MESH_TRIANGLES` from its 84-byte header before the rest is read.

The path is relative to the fixture file's folder and must stay inside it (after following
symbolic links): an absolute path or ``../`` out of the folder is refused. A fixture file is
what people share, run in batches and name in plan files; a fixture that reaches out of its
folder would read files its user never handed over (``/etc/...``, a home folder), and would not
travel with its folder. Subfolders are fine (``file = "parts/bracket.stl"``).

The bytes then go to :func:`fixplan.geometry.mesh.parse_mesh`, which checks the mesh itself.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from fixplan import limits
from fixplan.files import UnreadableFile, open_user_file, write_output
from fixplan.geometry.mesh import MESH_SUFFIXES, STL_HEADER_BYTES, Mesh, MeshError, declared_stl_triangles, parse_mesh
from fixplan.settings import DEFAULT, MeshSettings


def mesh_path(file: str, base_dir: Path) -> Path:
    """The mesh file ``file`` names, relative to ``base_dir``; :class:`MeshError` when it leaves the folder."""
    if Path(file).is_absolute():
        raise MeshError(f"{file!r} is an absolute path (expected a path relative to the fixture file's folder)")
    path = base_dir / file
    root = os.path.realpath(base_dir)
    real = os.path.realpath(path)
    if os.path.commonpath([root, real]) != root:
        raise MeshError(
            f"{file!r} is outside the fixture file's folder (it resolves to {real}; expected a file in that folder "
            "or below it, so that a fixture reads only what travels with it)"
        )
    return path


def declared_elements(data: bytes, kind: str) -> int | None:
    """The most faces or vertices a text header or the text itself announces, counted before parsing.

    PLY: the ``element vertex N`` and ``element face N`` lines of its header (a parser would
    allocate for them); OBJ: its ``f`` lines; ASCII STL: its ``facet`` keywords. None for a binary
    STL (its count was checked from the header).
    """
    if kind == "ply":
        end = data.find(b"end_header")
        header = data[: end if end >= 0 else 4096]
        counts = [
            int(words[2])
            for line in header.splitlines()
            if len(words := line.split()) == 3 and words[0] == b"element" and words[2].isdigit()
        ]
        return max(counts, default=0)
    if kind == "obj":
        return data.count(b"\nf ") + data.startswith(b"f ")
    if kind == "stl" and data.lstrip()[:5].lower() == b"solid":
        return data.count(b"facet") // 2  # "facet normal" ... "endfacet"
    return None


def load_mesh_file(
    file: str,
    base_dir: Path,
    *,
    units: str = "m",
    settings: MeshSettings = DEFAULT.mesh,
    tolerance_m: float | None = None,
) -> Mesh:
    """The checked mesh of a fixture's ``workpiece.file`` (module docstring); its ``notes`` say what was repaired.

    A STEP file (``.step``, ``.stp``) is tessellated to ``tolerance_m`` (default
    ``settings.step_tolerance_m``) by the optional CAD extra (:mod:`fixplan.geometry.step`); its
    coordinates come in the unit the file states, so ``units`` is not used for it.

    Raises
    ------
    MeshError
        One line saying why the file cannot be the part: where it is, what it is, how large, or
        what is wrong with the mesh (a STEP file without the extra: how to install it).
    """
    from fixplan.geometry.step import STEP_SUFFIXES

    path = mesh_path(file, base_dir)
    suffix = path.suffix.lower()
    step = suffix in STEP_SUFFIXES
    if not step and suffix not in MESH_SUFFIXES:
        raise MeshError(
            f"{file!r} has the suffix {suffix or '(none)'!r} (expected a mesh file: "
            f"{', '.join(MESH_SUFFIXES)}; or {', '.join(STEP_SUFFIXES)} with {_step_hint()})"
        )
    kind = "step" if step else MESH_SUFFIXES[suffix]
    expected = "a STEP file" if step else f"a {kind.upper()} mesh file"
    try:
        with open_user_file(path, expected=expected, max_bytes=limits.MAX_MESH_BYTES) as fh:
            size = os.fstat(fh.fileno()).st_size
            head = fh.read(STL_HEADER_BYTES)
            if kind == "stl":
                declared = declared_stl_triangles(head, size)
                if declared is not None and declared > limits.MAX_MESH_TRIANGLES:
                    raise MeshError(
                        f"{file!r} declares {declared} triangles in its binary STL header "
                        f"(expected at most {limits.MAX_MESH_TRIANGLES})"
                    )
            data = head + fh.read(limits.MAX_MESH_BYTES + 1 - len(head))
    except UnreadableFile as exc:
        raise MeshError(f"{file!r}: cannot read: {exc.reason}") from None
    except OSError as exc:
        raise MeshError(f"{file!r}: cannot read: {exc.strerror or exc}") from None
    if len(data) > limits.MAX_MESH_BYTES:
        raise MeshError(f"{file!r} is larger than the limit of {limits.MAX_MESH_BYTES} bytes")
    declared = declared_elements(data, kind)
    if declared is not None and declared > limits.MAX_MESH_TRIANGLES:
        raise MeshError(
            f"{file!r} declares {declared} faces or vertices (expected at most {limits.MAX_MESH_TRIANGLES} triangles)"
        )
    if step:
        mesh = _step_mesh(file, data, settings, settings.step_tolerance_m if tolerance_m is None else tolerance_m)
    else:
        mesh = parse_mesh(data, kind, units=units, settings=settings, max_triangles=limits.MAX_MESH_TRIANGLES)
    extent = float((mesh.vertices.max(axis=0) - mesh.vertices.min(axis=0)).max())
    farthest = float(abs(mesh.vertices).max())
    if not limits.SIZE.contains(extent) or farthest > limits.LENGTH_MAX_M:
        hint = ' (is the file in millimetres? set units = "mm")' if units == "m" and extent > 1.0 else ""
        raise MeshError(
            f"{file!r}: the part is {extent:g} m across, {farthest:g} m from its origin at most (expected "
            f"{limits.SIZE.expected()} across, within {limits.LENGTH_MAX_M:g} m of the origin){hint}"
        )
    return mesh


def _step_hint() -> str:
    from fixplan.geometry.step import INSTALL_HINT

    return f"the CAD extra: {INSTALL_HINT}"


def _step_mesh(file: str, data: bytes, settings: MeshSettings, tolerance_m: float) -> Mesh:
    """The checked mesh of a STEP file's bytes, tessellated to ``tolerance_m`` (:mod:`fixplan.geometry.step`)."""
    from fixplan.geometry.mesh import mesh_from_triangles
    from fixplan.geometry.step import step_triangles, tessellation_note

    try:
        with tempfile.TemporaryDirectory(prefix="fixplan-step-") as folder:
            copy = Path(folder) / "part.step"  # the bytes read under the limits, not the user's path
            write_output(copy, lambda path: path.write_bytes(data))
            vertices, faces = step_triangles(copy, tolerance_m, settings.step_angular_rad)
    except MeshError as exc:
        raise MeshError(f"{file!r} {exc}") from None
    if faces.shape[0] > limits.MAX_MESH_TRIANGLES:
        raise MeshError(
            f"{file!r} tessellates to {faces.shape[0]} triangles at a tolerance of {tolerance_m:g} m "
            f"(expected at most {limits.MAX_MESH_TRIANGLES}: a coarser workpiece.tolerance)"
        )
    note = tessellation_note(tolerance_m, settings.step_angular_rad, int(faces.shape[0]))
    return mesh_from_triangles(vertices, faces, settings=settings, read_notes=(note,))


__all__ = ["declared_elements", "load_mesh_file", "mesh_path"]
