"""Valid ranges of every quantity fixplan reads, from the physics and the solvers' scaling.

A fixture or a command line with a value outside its range is refused with the key and the
range (``workpiece.mass: got 1e-300 (expected a mass [kg] in [1e-06, 1e+04])``). Inside the
ranges every command either gives finite results or says why not. The ranges are documented in
``docs/limits.md``; keep that page and this table in step (``tests/test_limits.py`` checks it).

Why these numbers:

* lengths: a workpiece from 0.1 mm to 100 m. The touch and penetration tolerances are 1 µm
  (:mod:`fixplan.settings`), so a part must be much larger than that; 100 m is beyond any
  fixture and keeps a file written in millimetres (a "200 m box") from passing.
* coordinates within 1 km of the origin: float64 then resolves 10⁻¹³ m, far below 1 µm.
* mass 1 mg to 10 t, gravity within 100 m/s² (10 g) per axis, wrenches within 10⁶ N and
  10⁶ N·m: the cone programs and the contact solver work in ratios of applied to weight
  forces, and these bounds keep those ratios within ~10¹⁵, where float64 still has digits.
* friction ≤ 10 (measured coefficients are below ~4); tip and torsional radii ≤ 1 m.
* angles within ±360°; time steps 1 µs to 1 s; solver tolerances 10⁻¹⁴ to 1.
* inertia moments between 10⁻³ of the shape's uniform-density moment and m·R² (R: the shape's
  farthest point from the centre of mass), a bound no rigid body can exceed.
* at most 100 locators and contacts in a file, at most 1 MiB per input file, at most 10⁷
  simulation steps per run without ``--force``.
* a mesh part: at most 2·10⁵ triangles and 64 MiB (checking it at load takes about 0.8 s for
  10⁴ triangles and 16 s for 2·10⁵ here).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fixplan.errors import InputError


@dataclass(frozen=True)
class Range:
    """A closed interval ``[low, high]`` of a quantity, with what it is and its unit."""

    what: str  # "a mass"
    unit: str  # "kg" ("" for a pure number)
    low: float
    high: float

    def contains(self, value: float) -> bool:
        return math.isfinite(value) and self.low <= value <= self.high

    def expected(self) -> str:
        """``a mass [kg] in [1e-06, 1e+04]``: the words a message puts after "expected"."""
        unit = f" [{self.unit}]" if self.unit else ""
        return f"{self.what}{unit} in [{self.low:g}, {self.high:g}]"


LENGTH_MAX_M = 100.0
COORDINATE_MAX_M = 1000.0
FORCE_MAX_N = 1e6
TORQUE_MAX_NM = 1e6

MASS = Range("a mass", "kg", 1e-6, 1e4)
SIZE = Range("a length", "m", 1e-4, LENGTH_MAX_M)
COORDINATE = Range("a coordinate", "m", -COORDINATE_MAX_M, COORDINATE_MAX_M)
GRAVITY = Range("a gravity component", "m/s²", -100.0, 100.0)
ANGLE = Range("an angle", "deg", -360.0, 360.0)
TIP_RADIUS = Range("a tip radius", "m", 0.0, 1.0)
TORSION = Range("a torsional radius", "m", 0.0, 1.0)
FRICTION = Range("a friction coefficient", "", 0.0, 10.0)
STEP_TOLERANCE = Range("a chordal tolerance", "m", 1e-6, 1e-2)  # a STEP part's tessellation (workpiece.tolerance)
NORMAL = Range("a normal component", "", -1e300, 1e300)  # any finite direction; normalised on load
MAX_FORCE = Range("a force", "N", 1e-6, FORCE_MAX_N)
MAX_TORQUE = Range("a torque", "N·m", 1e-9, TORQUE_MAX_NM)
TIMESTEP = Range("a time step", "s", 1e-6, 1.0)
RESTITUTION = Range("a restitution coefficient", "", 0.0, 1.0)
SOLVER_TOLERANCE = Range("a solver tolerance", "", 1e-14, 1.0)
WRENCH_FORCE = Range("a force component", "N", -FORCE_MAX_N, FORCE_MAX_N)
WRENCH_TORQUE = Range("a moment component", "N·m", -TORQUE_MAX_NM, TORQUE_MAX_NM)
ACCELERATION = Range("an acceleration component", "m/s² or rad/s²", -1e3, 1e3)
DURATION = Range("a duration", "s", 0.0, 1e6)
REPEATABILITY = Range("a repeatability", "m", 0.0, 0.1)  # a robot's pose noise ([robot] repeatability)

INERTIA_MIN_OF_UNIFORM = 1e-3  # least given moment, as a fraction of the uniform-density moment
MAX_ENTRIES = 100  # [[locator]] plus [[contact]] entries in one file
MAX_FILE_BYTES = 1 << 20  # any input file fixplan reads as text (fixture, wrench CSV, plan JSON)
# a mesh part's file ([workpiece] shape = "mesh"): the checks at load are the cost, and every
# command loads the fixture (measured here: about 0.8 s for 10⁴ triangles, 5 s for 5·10⁴, 16 s for
# 2·10⁵, most of it the self-intersection test). A binary STL's header count, and the counts a
# PLY header or an OBJ/ASCII STL text announces, are checked before trimesh parses the file.
MAX_MESH_TRIANGLES = 200_000
MAX_MESH_BYTES = 64 << 20  # 64 MiB: a binary STL of 10⁶ triangles is 50 MB; ASCII ~250 bytes a triangle
MAX_SIM_STEPS = 10_000_000  # simulation steps of one `fixplan simulate` run without --force
MAX_NAME_LENGTH = 64
# tables, arrays and dotted-key levels nested in a TOML input, counted before parsing: a fixture
# nests 3 (workpiece.start.position); tomllib's cost grows with the square of a dotted key's
# depth (40,000 levels in 82 KB took minutes), so the file-size limit alone does not bound it
MAX_TOML_NESTING = 32
MAX_JSON_DEPTH = 64  # nesting of a plan file's JSON (a plan nests 6 deep): bounded before parsing
MAX_NUMBER_DIGITS = 400  # characters of one JSON number (a float has at most 17 significant digits)

# FCLib problems (`fixplan fclib`): the declared shape of every HDF5 dataset is checked against these
# before any data is read, so a small file cannot ask for gigabytes (docs/limits.md, docs/fclib.md).
# The largest problem at hand has 7 002 contacts and a W with 125 806 stored entries.
FCLIB_MAX_CONTACTS = 100_000  # contacts of one problem (len(mu))
FCLIB_MAX_NNZ = 10_000_000  # stored entries of one matrix (W, M or H; also of Hᵀ M⁻¹ H when condensing)
FCLIB_MAX_DOFS = 1_000_000  # rows of M (velocities) of a global problem
FCLIB_MAX_CHUNKS = 10_000  # chunks of one dataset (each costs an index lookup and a filter call: ~10 µs)
FCLIB_MAX_LINKS = 1_000  # links in the whole file (an FCLib file has about 30)
FCLIB_MAX_DEPTH = 8  # nested groups (FCLib uses 3: /fclib_local/W/x)
FCLIB_MAX_TEXT_BYTES = 1 << 16  # info/title, info/description: longer ones are not read
# every real entry of W, M, H, q, f, w (μ uses FRICTION): the solvers square norms of q, r and u = W r + q,
# and ±1e20 keeps those sums far from float64's 1.8e308 at any accepted size (the files at hand stay below 5e4)
FCLIB_ENTRY = Range("an FCLib matrix or vector entry", "", -1e20, 1e20)

# plausible densities of a solid part [kg/m³]: outside, validate warns (a file in millimetres?)
DENSITY_WARN_KGPM3 = (5.0, 5e4)

ALL: dict[str, Range] = {
    "workpiece.mass": MASS,
    "workpiece.size, radius, length, vertices (extent)": SIZE,
    "positions, points, start/goal position, --at": COORDINATE,
    "scene.gravity (each component)": GRAVITY,
    "rpy_deg, angle_deg": ANGLE,
    "locator.radius": TIP_RADIUS,
    "torsion": TORSION,
    "friction": FRICTION,
    "workpiece.tolerance (a STEP part's tessellation)": STEP_TOLERANCE,
    "manipulator.max_force": MAX_FORCE,
    "manipulator.max_torque": MAX_TORQUE,
    "simulation.timestep, --dt": TIMESTEP,
    "simulation.restitution": RESTITUTION,
    "simulation.tolerance, --tolerance": SOLVER_TOLERANCE,
    "--wrench, --wrenches forces": WRENCH_FORCE,
    "--wrench, --wrenches moments": WRENCH_TORQUE,
    "--motion": ACCELERATION,
    "--duration": DURATION,
}


def wrench_ranges(ndof: int) -> list[Range]:
    """The range of each wrench component: ``Fx,Fy,Fz,Tx,Ty,Tz`` (3D) or ``Fx,Fy,Mz`` (2D)."""
    forces = 3 if ndof == 6 else 2
    return [WRENCH_FORCE] * forces + [WRENCH_TORQUE] * (ndof - forces)


def parse_numbers(
    text: str, what: str, n: int | None = None, ranges: list[Range] | Range | None = None
) -> NDArray[np.float64]:
    """Comma-separated finite numbers, ``n`` of them, each inside its range (when given); :class:`InputError` names ``what``."""
    from fixplan.errors import quote_number, shorten

    shown = shorten(text)
    parts = text.split(",")
    try:
        values = np.array([float(x) for x in parts], dtype=float)
    except ValueError:
        raise InputError(f"{what} must be comma-separated numbers, got {shown}") from None
    if n is not None and values.shape[0] != n:
        raise InputError(f"{what} expects {n} numbers, got {values.shape[0]} in {shown}")
    if not np.all(np.isfinite(values)):
        raise InputError(f"{what} must be finite numbers, got {shown}")
    if ranges is not None:
        per = ranges if isinstance(ranges, list) else [ranges] * len(values)
        for i, (x, rng) in enumerate(zip(values, per, strict=False)):
            if not rng.contains(float(x)):
                # the number as typed: ":g" rounded 1000000.1 to the limit itself
                raise InputError(f"{what}: number {i + 1} is {quote_number(parts[i])} (expected {rng.expected()})")
    return values


# the characters the nesting scan stops at (everything else — bare-key characters, blanks — is skipped in C)
_TOML_STOPS = re.compile(r"""[^A-Za-z0-9_\- \t]""")
_BASIC_END = re.compile(r'(?:[^"\\\n]|\\.)*"')  # the rest of a one-line "..." string
_BASIC_ML_END = re.compile(r'(?:[^"\\]|\\.|"(?!""))*"""', re.S)  # the rest of a multi-line one


def toml_nesting(text: str, limit: int = MAX_TOML_NESTING) -> tuple[int, int] | None:
    """``(line, depth)`` where TOML ``text`` first nests deeper than ``limit``, else None (one linear scan).

    The depth counts the levels a parser builds,
    outside strings and comments: each ``[`` or ``{`` of a value, each dot of a dotted key
    (``a.b.c = 1`` nests 3), and the table header's levels under which its keys nest
    (``[a.b]``: 2, ``[[a.b]]``: 3). A key's dots count for the value it opens
    (``a.b = {c.d = [[1]]}`` nests 5: a, b, c, d and the inner array). Not a validator: text
    the scan cannot follow (an unterminated string) is left to the parser, which reports it.
    """
    line, pos, n = 1, 0, len(text)
    stack: list[tuple[int, int, str]] = []  # per open bracket: (depth, key dots) to restore on close, and "[" or "{"
    depth = 0  # levels of the table header ([a.b]: 2, [[a.b]]: 3), the open brackets and their keys
    key_dots = 0  # dots of the current entry's key (set at "=")
    chain = 0  # dots of the dotted name being read
    valued = False  # a top-level statement's "=" was read (a "[" is then a value, not a header)
    in_value = False  # reading a value (a dot there is a number's or a date's, not a key's)
    header = 0  # brackets of the table header being read (0: not in one)
    while True:
        m = _TOML_STOPS.search(text, pos)
        if m is None:
            return None
        i = m.start()
        c = text[i]
        pos = i + 1
        if c == ".":
            if in_value:
                continue
            chain += 1
            levels = depth + chain + (0 if header else 1)  # a.b.c = 1: 3 levels; [a.b.c]: 3 too
            if levels > limit:
                return line, levels
            continue
        if c == '"' or c == "'":
            triple = text.startswith(c * 3, i)
            if triple and c == "'":
                close = text.find("'''", i + 3)
                end = close + 3 if close >= 0 else 0
            elif c == "'":
                close, nl = text.find("'", i + 1), text.find("\n", i + 1)
                end = close + 1 if close >= 0 and not 0 <= nl < close else 0
            else:
                em = (_BASIC_ML_END if triple else _BASIC_END).match(text, i + (3 if triple else 1))
                end = em.end() if em else 0
            if end <= 0:
                return None  # unterminated: the parser says so
            line += text.count("\n", i, end)
            pos = end
            continue  # a quoted key segment: the dotted name goes on
        if c == "#":
            nl = text.find("\n", i)
            pos = n if nl < 0 else nl
            continue
        if c == "\n":
            line += 1
            chain = 0
            if not stack:
                key_dots, valued, in_value = 0, False, False
            continue
        if c == "=":
            key_dots, chain = chain, 0
            valued = valued or not stack
            in_value = True
        elif c == "[" and (header or not (stack or valued)):
            if not header:
                depth = 0  # a new table: its keys nest under its header only
            header += 1
            stack.append((depth, key_dots, "["))
            depth += 1
            if depth > limit:
                return line, depth
        elif header and c == "]":
            depth, key_dots, _ = stack.pop() if stack else (0, 0, "[")
            if not stack:
                depth = header + chain
                header = chain = 0
        elif c in "[{":
            stack.append((depth, key_dots, c))
            depth += 1 + key_dots
            key_dots = chain = 0
            in_value = c == "["  # an array holds values, an inline table keys
            if depth > limit:
                return line, depth
        elif c in "]}":
            if stack:
                depth, key_dots, _ = stack.pop()
            chain = 0
            in_value = True  # the bracket closed a value
        elif c == ",":
            key_dots = chain = 0
            in_value = bool(stack) and stack[-1][2] == "["
        else:
            chain = 0
