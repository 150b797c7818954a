"""Twins of a fixture: the same fixture in a rotated world, or its mirror image, as a document or text.

A planner whose answer depends on where the world's axes point, or on which hand the fixture
is built for, is wrong: a rigid motion or a reflection of the whole world (locators, pins, bores, start,
goal, gravity, explicit contacts) changes no gap, no normal force and no friction cone, so the
twin has the same plan, in the twin's frame. These functions build such twins on the parsed
TOML document (``tomllib``'s dict) so tests, benchmarks and ``fixplan generate --rotate-world``
share one definition:

- :func:`rotate_world` ``(doc, R)``: every world point ``x → R x``, every world direction
  ``d → R d``, every pose ``(R_wb, p) → (R R_wb, R p)``; body-frame data (shape, vertices,
  inertia, face hints) is unchanged.
- :func:`mirror_world` ``(doc, normal, offset_m)``: the reflection ``x → M x + 2 d n`` through
  the plane ``n·x = d`` (``M = I − 2 n nᵀ``, ``det M = −1``). A pose cannot be reflected by a
  rotation alone, so the body is reflected too, by ``S`` = the flip of one body axis ``k``:
  the mirrored pose is ``(M R_wb S, M p + 2 d n)`` (a proper rotation: ``det = (−1)(−1)``) and
  the body geometry becomes ``S`` of itself, so every world point of the part is
  ``M R_wb S (S x_b) + M p + 2 d n = M (R_wb x_b + p) + 2 d n``, its reflection. Boxes,
  rectangles, cylinders, spheres and disks are symmetric under ``S`` (their files do not
  change, face hints on axis ``k`` swap sign); polygon vertices are flipped and their order
  reversed to stay counter-clockwise; principal inertias are unchanged.
- :func:`rename_locators` ``(doc, mapping, order)``: new names and a new order of the
  ``[[locator]]`` entries (a mirrored fixture is a different build: its locators may be listed
  in another order under other names).

Pins and bores are world data, holes body data: a ``[[pin]]``'s base is a point, its axis and a
diamond pin's ``land_direction`` directions; a ``[[bore]]``'s mouth a point and its axis a
direction; a ``[[workpiece.hole]]`` (body frame) is unchanged by a rotation and flipped with the
body by ``S`` in a mirror (its mouth ``S p``, its axis ``S a``). A mirror changes handedness, so
only geometry with a mirror symmetry of its own survives it unchanged: holes, bores and round pins
are surfaces of revolution (symmetric about every plane through their axis), and a diamond pin's
two lands, arcs of equal width centred on ``±land_direction``, are symmetric about the plane of
its axis and its land direction: the reflection of a diamond pin is the diamond pin with the
reflected land direction. Nothing of a pin fixture is chiral, so every one has a mirror twin.

A ``[robot]``'s base is a world pose (rotated like the start; its grasp, in the body frame, is
unchanged); a robot has no mirror twin (the mirror image of an arm is another arm, whose joints
turn the other way: its URDF would have to be reflected), so :func:`mirror_world` refuses one.

The twin's gaps equal the original's at every pose mapped the same way (to rounding:
:func:`fixture_toml` writes every number with ``repr``, so the written twin loads to the bit
of the computed one). Mesh workpieces are refused by the mirror (their file cannot be reflected
here).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.errors import InputError
from fixplan.fixture import parse_toml
from fixplan.settings import DEFAULT
from fixplan.spatial import matrix_from_quaternion_wxyz, matrix_from_rpy, rot2, rpy_from_matrix

FloatArray = NDArray[np.float64]
_GRAVITY = {2: [0.0, -9.81], 3: [0.0, 0.0, -9.81]}  # the loader's defaults, written out in a twin
_SYMMETRIC_SHAPES = ("box", "rectangle", "cylinder", "sphere", "disk")


def dimension_of(doc: Mapping[str, Any]) -> int:
    """The document's scene dimension (3 when not given, as the loader reads it)."""
    dim = (doc.get("scene") or {}).get("dimension", 3)
    if dim not in (2, 3):
        raise InputError(f"scene.dimension must be 2 or 3, got {dim!r}")
    return int(dim)


def random_rotation(rng: np.random.Generator, dimension: int) -> FloatArray:
    """A uniformly random rotation: Haar-uniform on SO(3) (a normalised Gaussian quaternion), a uniform angle in 2D."""
    if dimension == 2:
        return rot2(float(rng.uniform(-math.pi, math.pi)))
    if dimension == 3:
        return matrix_from_quaternion_wxyz(rng.standard_normal(4))
    raise InputError(f"dimension must be 2 or 3, got {dimension!r}")


def rotate_world(doc: Mapping[str, Any], R: ArrayLike) -> dict[str, Any]:
    """The fixture document in a world turned by the rotation ``R`` about the origin (module docstring)."""
    dim = dimension_of(doc)
    Rw = np.asarray(R, dtype=float)
    if Rw.shape != (dim, dim):
        raise InputError(f"expected a {dim}×{dim} rotation for a {dim}D fixture, got shape {Rw.shape}")
    if not np.allclose(Rw @ Rw.T, np.eye(dim), atol=DEFAULT.numerics.zero_rel) or np.linalg.det(Rw) < 0:
        raise InputError("expected a rotation matrix (orthonormal, determinant +1)")
    return _map_world(doc, dim, Rw, np.zeros(dim), flip_axis=None)


def mirror_world(doc: Mapping[str, Any], normal: ArrayLike, offset_m: float = 0.0) -> dict[str, Any]:
    """The fixture document reflected through the plane ``normal · x = offset_m`` (module docstring).

    ``normal`` need not be unit length. The flipped body axis is the one most aligned with the
    plane's normal at the start pose (a box mirrored through ``y = 0`` keeps an unrotated pose).
    """
    dim = dimension_of(doc)
    n = np.asarray(normal, dtype=float)
    if n.shape != (dim,) or not np.all(np.isfinite(n)) or float(np.linalg.norm(n)) == 0.0:
        raise InputError(f"expected a nonzero {dim}-vector as the mirror plane's normal, got {normal!r}")
    if doc.get("robot") is not None:
        raise InputError(
            "cannot mirror a fixture with a [robot] (the mirror image of an arm is another arm: its URDF "
            "would have to be reflected; expected a fixture without [robot])"
        )
    n = n / np.linalg.norm(n)
    M = np.eye(dim) - 2.0 * np.outer(n, n)
    R_start = _pose_matrix(((doc.get("workpiece") or {}).get("start")) or {}, dim)
    flip_axis = int(np.argmax(np.abs(R_start.T @ n)))
    return _map_world(doc, dim, M, 2.0 * float(offset_m) * n, flip_axis=flip_axis)


def rename_locators(
    doc: Mapping[str, Any], mapping: Mapping[str, str], order: Sequence[str] | None = None
) -> dict[str, Any]:
    """The document with locators renamed by ``mapping`` (names not in it stay) and listed in ``order``.

    ``order`` lists the NEW names, each once (default: the file's order).
    """
    out = copy.deepcopy(dict(doc))
    locators = out.get("locator") or []
    for entry in locators:
        entry["name"] = mapping.get(entry["name"], entry["name"])
    names = [entry["name"] for entry in locators]
    if len(set(names)) != len(names):
        raise InputError(f"renaming makes locator names repeat: {', '.join(names)}")
    if order is not None:
        if sorted(order) != sorted(names):
            raise InputError(
                f"order must list every locator once (expected {', '.join(names)}, got {', '.join(order)})"
            )
        by_name = {entry["name"]: entry for entry in locators}
        out["locator"] = [by_name[name] for name in order]
    return out


# -- the map ----------------------------------------------------------------------------------------


def _pose_matrix(pose: Mapping[str, Any], dim: int) -> FloatArray:
    if dim == 3:
        return matrix_from_rpy(np.radians(np.asarray(pose.get("rpy_deg", [0.0, 0.0, 0.0]), dtype=float)))
    return rot2(math.radians(float(pose.get("angle_deg", 0.0))))


def _map_world(doc: Mapping[str, Any], dim: int, A: FloatArray, t: FloatArray, flip_axis: int | None) -> dict[str, Any]:
    """``x → A x + t`` on every world quantity; ``flip_axis``: the body axis reflected with it (when det A = −1)."""
    out = copy.deepcopy(dict(doc))
    S = np.eye(dim)
    if flip_axis is not None:
        S[flip_axis, flip_axis] = -1.0

    def point(p: Any) -> list[float]:
        return [float(v) for v in A @ np.asarray(p, dtype=float) + t]

    def direction(d: Any) -> list[float]:
        return [float(v) for v in A @ np.asarray(d, dtype=float)]

    scene = out.setdefault("scene", {})
    scene["gravity"] = direction(scene.get("gravity", _GRAVITY[dim]))
    wp = out.setdefault("workpiece", {})
    if flip_axis is not None:
        _mirror_body(wp, dim, flip_axis)
    wp.setdefault("start", {})
    for key in ("start", "goal"):
        if key not in wp:
            continue
        pose = wp[key]
        wp[key] = _mapped_pose(pose, A @ _pose_matrix(pose, dim) @ S, point, dim)
    for entry in out.get("locator") or []:
        entry["position"] = point(entry["position"])
        if flip_axis is not None and "face" in entry:
            entry["face"] = _flipped_face(entry["face"], flip_axis)
    for entry in out.get("pin") or []:  # world frame: the base a point, the axis and the lands' direction directions
        entry["position"] = point(entry["position"])
        entry["axis"] = direction(entry["axis"])
        if "land_direction" in entry:
            entry["land_direction"] = direction(entry["land_direction"])
    for entry in out.get("bore") or []:  # world frame: the mouth a point, the axis a direction
        entry["position"] = point(entry["position"])
        entry["axis"] = direction(entry["axis"])
    robot = out.get("robot")
    if isinstance(robot, dict) and isinstance(robot.get("base"), dict):  # a world pose (the grasp is body frame)
        robot["base"] = _mapped_pose(robot["base"], A @ _pose_matrix(robot["base"], dim), point, dim)
    for entry in out.get("contact") or []:
        entry["point"] = point(entry["point"])
        entry["normal"] = direction(entry["normal"])
    for entry in out.get("clamp") or []:
        entry["position"] = point(entry["position"])
        entry["direction"] = direction(entry["direction"])
    sign = float(np.sign(np.linalg.det(A)))  # a moment is a pseudo-vector: a mirror turns it over
    for entry in out.get("load") or []:  # about the body origin, which moves with the part
        w = np.asarray(entry["wrench"], dtype=float)
        moment = sign * (A @ w[3:]) if dim == 3 else sign * w[2:]
        entry["wrench"] = [*direction(w[:dim]), *(float(v) for v in moment)]
    for entry in out.get("obstacle") or []:  # planes map as a point and a normal, boxes as a pose
        if "point" in entry:
            entry["point"] = point(entry["point"])
        if "normal" in entry:
            entry["normal"] = direction(entry["normal"])
        if isinstance(entry.get("pose"), dict):
            pose = entry["pose"]
            R_box = A @ _pose_matrix(pose, dim)
            if np.linalg.det(R_box) < 0:  # a mirrored box is the same box: flip one of its (symmetric) axes
                R_box = R_box @ np.diag([-1.0] + [1.0] * (dim - 1))
            entry["pose"] = _mapped_pose(pose, R_box, point, dim)
    return out


def _mapped_pose(
    pose: Mapping[str, Any], R_new: FloatArray, point: Callable[[Any], list[float]], dim: int
) -> dict[str, Any]:
    """A pose table with its position mapped by ``point`` and its rotation ``R_new`` (``rpy_deg``, 2D ``angle_deg``)."""
    mapped: dict[str, Any] = {"position": point(pose.get("position", [0.0] * dim))}
    if dim == 3:
        mapped["rpy_deg"] = [float(v) for v in np.degrees(rpy_from_matrix(R_new))]
    else:
        mapped["angle_deg"] = math.degrees(math.atan2(R_new[1, 0], R_new[0, 0]))
    return mapped


def _flipped_face(face: str, axis: int) -> str:
    if len(face) == 2 and face[0] in "+-" and face[1] == "xyz"[axis]:
        return ("-" if face[0] == "+" else "+") + face[1]
    return face


def _mirror_body(wp: dict[str, Any], dim: int, axis: int) -> None:
    """Reflect the workpiece's body geometry by flipping body ``axis`` (in place)."""
    shape = wp.get("shape")
    for hole in wp.get("hole") or []:  # body frame: flipped with the body
        hole["position"] = [float(-v) if i == axis else float(v) for i, v in enumerate(hole["position"])]
        hole["axis"] = [float(-v) if i == axis else float(v) for i, v in enumerate(hole["axis"])]
    if shape == "polygon":
        flipped = [[float(-v[i]) if i == axis else float(v[i]) for i in range(dim)] for v in wp["vertices"]]
        wp["vertices"] = [flipped[0], *reversed(flipped[1:])]  # same first vertex, counter-clockwise again
    elif shape not in _SYMMETRIC_SHAPES:
        raise InputError(
            f"cannot mirror a {shape!r} workpiece (expected one of: polygon, {', '.join(_SYMMETRIC_SHAPES)})"
        )
    # Principal inertias (the diagonal) are unchanged by an axis flip: S diag(I) S = diag(I).


# -- text ------------------------------------------------------------------------------------------


def toml_value(x: Any, digits: int | None = None) -> str:
    """A TOML value, floats in full precision or rounded to ``digits`` significant digits.

    Full precision is ``repr``: the shortest text that reads back to the same float; the rounding
    keeps binary noise such as 0.30000000000000004 out of generated files.
    """
    if isinstance(x, bool):
        return "true" if x else "false"
    if isinstance(x, int | np.integer):
        return str(int(x))
    if isinstance(x, float | np.floating):
        v = float(x) if digits is None else float(f"{float(x):.{digits}g}")
        v += 0.0  # -0.0 written as 0.0
        if not math.isfinite(v):
            raise InputError(f"cannot write {v} in a fixture file (expected a finite number)")
        return repr(v)
    if isinstance(x, str):
        return '"' + x.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(x, list | tuple | np.ndarray):
        return "[" + ", ".join(toml_value(v, digits) for v in x) + "]"
    if isinstance(x, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v, digits)}" for k, v in x.items()) + " }"
    raise InputError(f"cannot write {type(x).__name__} in a fixture file")


def fixture_toml(doc: Mapping[str, Any]) -> str:
    """A fixture document as TOML text: top-level values, then tables, then arrays of tables."""
    scalars = [k for k, v in doc.items() if not isinstance(v, dict | list) or (isinstance(v, list) and not _tables(v))]
    tables = [k for k, v in doc.items() if isinstance(v, dict)]
    arrays = [k for k, v in doc.items() if isinstance(v, list) and _tables(v)]
    lines = [f"{k} = {toml_value(doc[k])}" for k in scalars]
    for k in tables:
        lines += ["", f"[{k}]", *(f"{kk} = {toml_value(vv)}" for kk, vv in doc[k].items())]
    for k in arrays:
        for entry in doc[k]:
            lines += ["", f"[[{k}]]", *(f"{kk} = {toml_value(vv)}" for kk, vv in entry.items())]
    return "\n".join(lines) + "\n"


def _tables(v: list) -> bool:
    return bool(v) and all(isinstance(e, dict) for e in v)


def header_of(text: str) -> str:
    """The comment lines that open a fixture file (its header), with their newlines."""
    head = []
    for line in text.splitlines(keepends=True):
        if not line.startswith("#"):
            break
        head.append(line if line.endswith("\n") else line + "\n")
    return "".join(head)


def twin_text(text: str, doc: Mapping[str, Any], note: str) -> str:
    """A twin's file: the original's header, ``note`` as comment lines, then ``doc`` as TOML."""
    comments = "".join(f"# {line}\n" for line in note.splitlines())
    return header_of(text) + comments + fixture_toml(doc)


def rotated_fixture_text(text: str, R: ArrayLike, source: str = "<string>") -> str:
    """The fixture text in a world turned by ``R`` (:func:`rotate_world`), header kept, the rotation noted."""
    doc = parse_toml(text, source)
    Rw = np.asarray(R, dtype=float)
    rows = "; ".join(", ".join(f"{v:.12g}" for v in row) for row in Rw)
    return twin_text(text, rotate_world(doc, Rw), f"World rotated about the origin by R = [{rows}].")


def mirrored_fixture_text(
    text: str,
    normal: ArrayLike,
    offset_m: float = 0.0,
    mapping: Mapping[str, str] | None = None,
    order: Sequence[str] | None = None,
    source: str = "<string>",
) -> str:
    """The fixture text reflected through ``normal · x = offset_m`` (:func:`mirror_world`), locators renamed."""
    doc = mirror_world(parse_toml(text, source), normal, offset_m)
    if mapping is not None or order is not None:
        doc = rename_locators(doc, mapping or {}, order)
    n = ", ".join(f"{v:.12g}" for v in np.asarray(normal, dtype=float))
    renamed = "" if not mapping else "; locators renamed " + ", ".join(f"{a} -> {b}" for a, b in mapping.items())
    return twin_text(text, doc, f"World mirrored through the plane n·x = {offset_m:g} m, n = [{n}]{renamed}.")


__all__ = [
    "dimension_of",
    "fixture_toml",
    "header_of",
    "mirror_world",
    "mirrored_fixture_text",
    "random_rotation",
    "rename_locators",
    "rotate_world",
    "rotated_fixture_text",
    "twin_text",
]
