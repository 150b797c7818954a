"""Rectilinear solids as closed triangle meshes: a union of cells of a grid (L-brackets, slots, pockets).

A part is the union of the cells ``filled[i, j, k]`` of the grid with planes ``xs``, ``ys``,
``zs`` (body frame, metres). Its surface is every cell face between a filled and an empty cell
(or the outside), each split into two triangles wound counter-clockwise seen from outside. Every
triangle's corners are grid points, so coplanar faces share their edges exactly (no T-junction),
and the surface is closed; it is manifold when no two filled cells meet only along an edge or at
a corner (:func:`cell_surface` refuses that). The part functions build the generated problem
parts of ``tools/mesh_parts.py`` and the accuracy tests' subdivided boxes; their closed forms
(volume, centre of mass, inertia) are sums over the cells.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import FixplanError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


def cell_surface(xs: FloatArray, ys: FloatArray, zs: FloatArray, filled: BoolArray) -> tuple[FloatArray, IntArray]:
    """``(vertices (n, 3), faces (m, 3))`` of the union of the filled cells (module docstring)."""
    xs, ys, zs = (np.asarray(a, dtype=float) for a in (xs, ys, zs))
    filled = np.asarray(filled, dtype=bool)
    shape = (len(xs) - 1, len(ys) - 1, len(zs) - 1)
    if filled.shape != shape:
        raise FixplanError(f"filled has shape {filled.shape} (expected {shape}: one per grid cell)")
    _check_manifold(filled)
    padded = np.zeros(tuple(s + 2 for s in shape), dtype=bool)
    padded[1:-1, 1:-1, 1:-1] = filled
    index: dict[tuple[int, int, int], int] = {}
    vertices: list[tuple[float, float, float]] = []
    faces: list[tuple[int, int, int]] = []

    def vid(p: tuple[int, int, int]) -> int:
        if p not in index:
            index[p] = len(vertices)
            vertices.append((float(xs[p[0]]), float(ys[p[1]]), float(zs[p[2]])))
        return index[p]

    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        step = np.zeros(3, dtype=int)
        step[axis] = 1
        inside = padded[1:-1, 1:-1, 1:-1]
        for sign in (1, -1):
            shifted = np.roll(padded, -sign, axis=axis)[1:-1, 1:-1, 1:-1]
            for cell in np.argwhere(inside & ~shifted):
                c = [int(x) for x in cell]
                base = list(c)
                if sign > 0:
                    base[axis] += 1  # the face at the cell's far plane along the axis
                corners = []
                for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    p = list(base)
                    p[u] += du
                    p[v] += dv
                    corners.append(vid((p[0], p[1], p[2])))
                a, b, cc, d = corners  # counter-clockwise about +axis (u, v, axis right-handed)
                if sign > 0:
                    faces += [(a, b, cc), (a, cc, d)]
                else:
                    faces += [(a, cc, b), (a, d, cc)]
    return np.array(vertices, dtype=float), np.array(faces, dtype=np.int64)


def _check_manifold(filled: BoolArray) -> None:
    """Refuse two filled cells meeting only along an edge or at a corner (a non-manifold surface)."""
    p = np.zeros(tuple(s + 2 for s in filled.shape), dtype=bool)
    p[1:-1, 1:-1, 1:-1] = filled
    # every 2×2×2 block of cells around a grid point: the bad patterns are two diagonal cells
    # with both others of their shared square (edge case) empty, or a lone corner pair
    blocks = np.stack(
        [
            p[i : p.shape[0] - 1 + i, j : p.shape[1] - 1 + j, k : p.shape[2] - 1 + k]
            for i in (0, 1)
            for j in (0, 1)
            for k in (0, 1)
        ],
        axis=-1,
    ).reshape(-1, 2, 2, 2)
    for block in blocks[blocks.reshape(-1, 8).sum(axis=1) >= 2]:
        if not _block_manifold(block):
            raise FixplanError("two filled cells meet only along an edge or at a corner (a non-manifold surface)")


def _block_manifold(block: BoolArray) -> bool:
    """The cells of a 2×2×2 block around a grid point meet through faces (filled and empty both connected)."""
    for target in (True, False):
        cells = [tuple(c) for c in np.argwhere(block == target)]
        if not cells:
            continue
        seen = {cells[0]}
        stack = [cells[0]]
        while stack:
            c = stack.pop()
            for n in cells:
                if n not in seen and sum(abs(a - b) for a, b in zip(c, n, strict=True)) == 1:
                    seen.add(n)
                    stack.append(n)
        if len(seen) != len(cells):
            return False
    return True


def cell_mass_properties(
    xs: FloatArray, ys: FloatArray, zs: FloatArray, filled: BoolArray
) -> tuple[float, FloatArray, FloatArray]:
    """Closed forms: ``(volume, centre, ∫(r·r I − r rᵀ) dV about the centre)``, summed over the cells (boxes)."""
    lo = np.stack(np.meshgrid(xs[:-1], ys[:-1], zs[:-1], indexing="ij"), axis=-1)[filled]
    hi = np.stack(np.meshgrid(xs[1:], ys[1:], zs[1:], indexing="ij"), axis=-1)[filled]
    size = hi - lo
    vol = np.prod(size, axis=1)
    centre = (lo + hi) / 2.0
    volume = float(vol.sum())
    com = (vol[:, None] * centre).sum(axis=0) / volume
    inertia = np.zeros((3, 3))
    for v, s, c in zip(vol, size, centre, strict=True):
        own = v / 12.0 * np.diag([s[1] ** 2 + s[2] ** 2, s[0] ** 2 + s[2] ** 2, s[0] ** 2 + s[1] ** 2])
        r = c - com
        inertia += own + v * (float(r @ r) * np.eye(3) - np.outer(r, r))
    return volume, com, inertia


def box_cells(size: tuple[float, float, float], n: int) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """A box of full edge lengths ``size`` centred on the origin, ``n`` cells per edge (``12 n²`` triangles)."""
    xs, ys, zs = (np.linspace(-s / 2.0, s / 2.0, n + 1) for s in size)
    return xs, ys, zs, np.ones((n, n, n), dtype=bool)


def l_bracket_cells(
    length: float, width: float, height: float, thickness: float
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """An L-bracket extruded along y: a base ``length`` × ``thickness`` (x, z) and a wall ``thickness`` × ``height``.

    Body frame: the outer corner of the L at the origin, the base along +x, the wall along +z,
    ``width`` along +y; the concave corner is the line ``x = z = thickness``.
    """
    xs = np.array([0.0, thickness, length])
    ys = np.array([0.0, width])
    zs = np.array([0.0, thickness, height])
    filled = np.zeros((2, 1, 2), dtype=bool)
    filled[:, 0, 0] = True  # the base
    filled[0, 0, 1] = True  # the wall
    return xs, ys, zs, filled


def slotted_block_cells(
    size: tuple[float, float, float], slot_width: float, slot_depth: float
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """A block centred on the origin (x, y) with its bottom at z = 0 and a slot along y across its top.

    The slot is ``slot_width`` wide (centred on x = 0) and ``slot_depth`` deep.
    """
    a, b, c = size
    xs = np.array([-a / 2.0, -slot_width / 2.0, slot_width / 2.0, a / 2.0])
    ys = np.array([-b / 2.0, b / 2.0])
    zs = np.array([0.0, c - slot_depth, c])
    filled = np.ones((3, 1, 2), dtype=bool)
    filled[1, 0, 1] = False
    return xs, ys, zs, filled


def housing_cells(
    size: tuple[float, float, float], wall: float, pocket_depth: float
) -> tuple[FloatArray, FloatArray, FloatArray, BoolArray]:
    """A block centred on the origin (x, y), bottom at z = 0, with a rectangular pocket in its top.

    The pocket leaves walls ``wall`` thick on all four sides and is ``pocket_depth`` deep.
    """
    a, b, c = size
    xs = np.array([-a / 2.0, -a / 2.0 + wall, a / 2.0 - wall, a / 2.0])
    ys = np.array([-b / 2.0, -b / 2.0 + wall, b / 2.0 - wall, b / 2.0])
    zs = np.array([0.0, c - pocket_depth, c])
    filled = np.ones((3, 3, 2), dtype=bool)
    filled[1, 1, 1] = False
    return xs, ys, zs, filled


__all__ = [
    "box_cells",
    "cell_mass_properties",
    "cell_surface",
    "housing_cells",
    "l_bracket_cells",
    "slotted_block_cells",
]
