"""Build the mesh parts of ``problems/meshes/`` and their fixtures: nothing is downloaded.

Three rectilinear parts from :mod:`fixplan.geometry.cells`, each located 3-2-1 by six spherical
tips, one of them (E1) inside a concave region, where the part's convex hull would put it inside
the part: an L-bracket (E1 against the wall's inner face), a slotted block (E1 in the slot,
against a slot wall) and a housing (E1 in the pocket, against an inner wall). Each part sits at
its located pose at the start (the identity: body frame = world frame). Their verdicts are
derived by hand in ``problems/meshes/expected.toml`` and checked by ``tests/test_mesh_problems.py``.

    python tools/mesh_parts.py           # write problems/meshes/
    python tools/mesh_parts.py --check   # exit 1 when a file there differs from what this writes
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from fixplan.geometry.cells import cell_surface, housing_cells, l_bracket_cells, slotted_block_cells
from fixplan.geometry.mesh import stl_bytes

OUT = Path(__file__).resolve().parents[1] / "problems" / "meshes"
RHO = 0.003  # tip radius [m]
MU = 0.3
ALUMINIUM, STEEL = 2700.0, 7850.0  # [kg/m³]


def obj_text(V: np.ndarray, F: np.ndarray) -> bytes:
    """An OBJ file of the triangles (every float64 digit)."""
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in V]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    return ("\n".join(lines) + "\n").encode()


def fixture_text(
    name: str, comment: str, file: str, units: str | None, mass: float, tips: list[tuple[str, tuple[float, ...]]]
) -> str:
    """The fixture TOML of a part: a comment block, the mesh workpiece at the identity, the tips."""
    head = "".join(f"# {line}\n" if line else "#\n" for line in comment.strip().splitlines())
    unit_line = f'units = "{units}"\n' if units else ""
    body = (
        f'format = 1\n\n[scene]\nname = "{name}"\ndimension = 3\n\n[workpiece]\nshape = "mesh"\nfile = "{file}"\n'
        f"{unit_line}mass = {mass!r}\nstart = {{ position = [0.0, 0.0, 0.0], rpy_deg = [0.0, 0.0, 0.0] }}\n"
    )
    for tip, centre in tips:
        pos = ", ".join(repr(round(float(x), 6)) for x in centre)
        body += f'\n[[locator]]\nname = "{tip}"\nposition = [{pos}]\nradius = {RHO}\nfriction = {MU}\n'
    return head + "\n" + body


def parts() -> dict[str, bytes]:
    """File name → bytes of every file this script writes."""
    out: dict[str, bytes] = {}
    r = RHO
    # L-bracket: base 0.1 x 0.04 x 0.01, wall 0.01 thick up to 0.06; outer corner at the origin
    cells = l_bracket_cells(0.1, 0.04, 0.06, 0.01)
    V, F = cell_surface(*cells)
    out["l-bracket.stl"] = stl_bytes(V * 1000.0, F)  # binary, millimetres
    volume = 0.1 * 0.04 * 0.01 + 0.01 * 0.04 * 0.05
    out["l-bracket.toml"] = fixture_text(
        "mesh-l-bracket",
        """
mesh-l-bracket: an aluminium L-bracket (tools/mesh_parts.py), binary STL in millimetres, located
3-2-1 at its start pose. E1 sits in the L's concave region against the wall's inner face
(x = 0.01 m): the convex hull fills that region; on it E1's gap would be -16 mm (its centre 13 mm
inside the hull, behind the outer face x = 0), on the real surface it is 0.
Base 0.1 x 0.04 x 0.01 m (x, y, z), wall 0.01 x 0.04 x 0.06 m at x in [0, 0.01]; body frame at the
L's outer corner. Centre of mass (0.035, 0.02, 0.015) m. Verdicts: problems/meshes/expected.toml.
""",
        "l-bracket.stl",
        "mm",
        round(ALUMINIUM * volume, 6),
        [
            ("B1", (0.015, 0.01, -r)),
            ("B2", (0.08, 0.01, -r)),
            ("B3", (0.04, 0.035, -r)),
            ("S1", (0.08, -r, 0.005)),
            ("S2", (0.005, -r, 0.045)),
            ("E1", (0.01 + r, 0.02, 0.035)),
        ],
    ).encode()
    # slotted block: 0.08 x 0.05 x 0.04, a slot 0.02 wide and 0.015 deep along y across the top
    V, F = cell_surface(*slotted_block_cells((0.08, 0.05, 0.04), 0.02, 0.015))
    out["slotted-block.stl"] = stl_bytes(V, F, ascii=True)  # ASCII, metres
    volume = 0.08 * 0.05 * 0.04 - 0.02 * 0.05 * 0.015
    out["slotted-block.toml"] = fixture_text(
        "mesh-slotted-block",
        """
mesh-slotted-block: a steel block with a slot across its top (tools/mesh_parts.py), ASCII STL in
metres, located 3-2-1 at its start pose. E1 sits in the slot against its wall x = -0.01 m: the
convex hull would fill the slot: on it E1's gap would be -10.5 mm (its centre 7.5 mm below the
hull's top face z = 0.04), on the real surface it is 0.
Block 0.08 x 0.05 x 0.04 m centred on x = y = 0 with its bottom at z = 0; slot x in [-0.01, 0.01],
z in [0.025, 0.04]. Centre of mass (0, 0, 0.0187069) m. Verdicts: problems/meshes/expected.toml.
""",
        "slotted-block.stl",
        None,
        round(STEEL * volume, 6),
        [
            ("B1", (-0.03, -0.015, -r)),
            ("B2", (0.03, -0.015, -r)),
            ("B3", (0.0, 0.02, -r)),
            ("S1", (-0.03, -0.025 - r, 0.01)),
            ("S2", (0.03, -0.025 - r, 0.03)),
            ("E1", (-0.01 + r, 0.0, 0.0325)),
        ],
    ).encode()
    # housing: 0.12 x 0.08 x 0.05 with a pocket leaving 0.01 walls, 0.03 deep
    V, F = cell_surface(*housing_cells((0.12, 0.08, 0.05), 0.01, 0.03))
    out["housing.obj"] = obj_text(V, F)
    volume = 0.12 * 0.08 * 0.05 - 0.1 * 0.06 * 0.03
    out["housing.toml"] = fixture_text(
        "mesh-housing",
        """
mesh-housing: an aluminium housing with a pocket (tools/mesh_parts.py), OBJ in metres, located
3-2-1 at its start pose. E1 sits in the pocket against its inner wall x = -0.05 m: the convex
hull would fill the pocket: on it E1's gap would be -16 mm (its centre 13 mm inside the hull,
behind the outer face x = -0.06), on the real surface it is 0.
Block 0.12 x 0.08 x 0.05 m centred on x = y = 0 with its bottom at z = 0; pocket 0.1 x 0.06 x 0.03 m
from the top. Centre of mass (0, 0, 0.019) m. Verdicts: problems/meshes/expected.toml.
""",
        "housing.obj",
        None,
        round(ALUMINIUM * volume, 6),
        [
            ("B1", (-0.04, -0.025, -r)),
            ("B2", (0.04, -0.025, -r)),
            ("B3", (0.0, 0.03, -r)),
            ("S1", (-0.04, -0.04 - r, 0.01)),
            ("S2", (0.04, -0.04 - r, 0.035)),
            ("E1", (-0.05 + r, 0.0, 0.035)),
        ],
    ).encode()
    return out


def main(argv: list[str] | None = None) -> int:
    """Write the files, or with ``--check`` return 1 when one in the repository differs."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="compare with problems/meshes/ instead of writing")
    args = parser.parse_args(argv)
    stale = []
    for name, data in parts().items():
        path = OUT / name
        if args.check:
            if not path.is_file() or path.read_bytes() != data:
                stale.append(name)
        else:
            OUT.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
            print(f"wrote {path}")
    if stale:
        print(f"stale in {OUT}: {', '.join(stale)} (run python tools/mesh_parts.py)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
