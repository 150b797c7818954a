"""Hypothesis strategies for hostile input: mutated fixture files, odd command lines, bad FCLib files.

Fixture mutations start from the files in ``problems/`` (parsed with tomllib) and change one to
three places: delete a key, replace a value by one of another type or an extreme number, add an
unknown key, duplicate or multiply entries, nest deeply. The document is written back as TOML
(every table inline, so any key or value survives the round trip), and a byte-level mutation may
follow: another encoding, invalid UTF-8, a NUL, a truncation, an HDF5 signature.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
from conftest import PROBLEMS, library  # noqa: F401  (re-exported: the fuzz tests import PROBLEMS from here)
from hypothesis import strategies as st

SEEDS = library()  # less the fixtures whose robot needs a missing extra
DOCUMENTS = {p.name: tomllib.loads(p.read_text(encoding="utf-8")) for p in SEEDS}


# -- writing TOML ------------------------------------------------------------------------------
def toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a TOML basic string
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, RawToml):
        return value.text
    raise TypeError(type(value))


class RawToml:
    """TOML text written as is (a 5000-digit integer, a deep nesting)."""

    def __init__(self, text: str):
        self.text = text

    def __repr__(self) -> str:
        return f"RawToml({self.text[:40]!r}{'...' if len(self.text) > 40 else ''})"


def to_toml(doc: dict[str, Any]) -> str:
    """One ``key = value`` line per top-level key (tables and arrays of tables inline)."""
    return "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in doc.items())


# -- values ------------------------------------------------------------------------------------
EXTREME_FLOATS = [
    0.0, -0.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300, 1e308, -1e308, 1.7976931348623157e308,
    math.inf, -math.inf, math.nan, 1e-9, 1e9, 1e6, -1.0, 2.0, 0.5, 1e-7, 200.0, 1000.0,
]  # fmt: skip
EXTREME_INTS = [0, -1, 1, 2, 3, 7, 10**400, -(10**400), 2**63, -(2**63) - 1, 10**19]
ODD_STRINGS = [
    "", " ", "B1", "B1\nB2", "\x1b[31mred\x1b[0m", "a,b", " P1 ", "x" * 500, "é", "\u202e", "nan", "1e400",
    "box", "rectangle", "mesh", "+z", "side", "\t", "\0", "[/x]", "[bold]b", "%s{0}",
]  # fmt: skip


def deep(depth: int) -> RawToml:
    return RawToml("[" * depth + "1" + "]" * depth)


scalars = st.one_of(
    st.sampled_from(EXTREME_FLOATS),
    st.sampled_from(EXTREME_INTS),
    st.sampled_from(ODD_STRINGS),
    st.booleans(),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.text(max_size=20),
)
values = st.one_of(
    scalars,
    st.lists(st.one_of(st.sampled_from(EXTREME_FLOATS), st.floats(-1e3, 1e3)), max_size=7),
    st.lists(scalars, max_size=4),
    st.just({}),
    st.dictionaries(st.sampled_from(["position", "rpy_deg", "angle_deg", "x"]), scalars, max_size=3),
    st.integers(min_value=50, max_value=3000).map(deep),
    st.just(RawToml("1" + "0" * 5000)),
)


# -- document mutations ------------------------------------------------------------------------
def paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every place in a parsed document (keys of tables, indices of lists)."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append((*prefix, k))
            out += paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append((*prefix, i))
            out += paths(v, (*prefix, i))
    return out


def _parent(doc: Any, path: tuple) -> Any:
    for p in path[:-1]:
        doc = doc[p]
    return doc


@st.composite
def mutated_document(draw: st.DrawFn) -> dict[str, Any]:
    name = draw(st.sampled_from(sorted(DOCUMENTS)))
    doc = json.loads(json.dumps(DOCUMENTS[name]))  # a deep copy (the documents hold JSON types only)
    for _ in range(draw(st.integers(1, 3))):
        places = paths(doc)
        if not places:
            break
        place = draw(st.sampled_from(places))
        parent = _parent(doc, place)
        op = draw(st.sampled_from(["replace", "replace", "replace", "delete", "unknown", "multiply", "scale"]))
        key = place[-1]
        if op == "replace":
            parent[key] = draw(values)
        elif op == "delete":
            del parent[key]
        elif op == "unknown" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["colour", "x\ny", "\x1b[1m", "mass ", "locator"]))] = draw(scalars)
        elif op == "multiply" and isinstance(parent, list) and parent:
            parent.extend([parent[key]] * draw(st.sampled_from([1, 2, 150])))
        elif op == "scale":
            value = parent[key]
            factor = draw(st.sampled_from([1e-300, 1e-6, 1e3, 1e6, 1e300, -1.0]))
            if isinstance(value, int | float) and not isinstance(value, bool):
                parent[key] = value * factor
            elif isinstance(value, list) and all(isinstance(v, int | float) for v in value):
                parent[key] = [v * factor for v in value]
    return doc


BOUNDARY_VALUES = [1e-6, 1e4, 100.0, -100.0, 10.0, 1e-4, 1000.0, -1000.0, 1.0, 0.0, 1e-3, 360.0, -360.0, 1e6, 1e-9]


@st.composite
def numeric_document(draw: st.DrawFn) -> dict[str, Any]:
    """A problem with one to three numbers changed, keeping types: many stay valid, near the range edges."""
    name = draw(st.sampled_from(sorted(DOCUMENTS)))
    doc = json.loads(json.dumps(DOCUMENTS[name]))
    numeric = [
        p
        for p in paths(doc)
        if isinstance(_parent(doc, p)[p[-1]], int | float) and p[-1] not in ("format", "dimension")
    ]
    for _ in range(draw(st.integers(1, 3))):
        place = draw(st.sampled_from(numeric))
        parent = _parent(doc, place)
        if draw(st.booleans()):
            parent[place[-1]] = draw(st.sampled_from(BOUNDARY_VALUES))
        else:
            parent[place[-1]] = float(parent[place[-1]]) * draw(st.sampled_from([1e-3, 0.5, 0.9, 1.1, 2.0, 1e3, -1.0]))
    return doc


BYTE_MUTATIONS = ("none", "none", "none", "utf16", "latin1", "invalid", "nul", "truncate", "bom", "hdf5", "crlf")


def ndof_of(doc: dict[str, Any]) -> int:
    """6 for a 3D document, 3 for a 2D one (3D when the dimension was mutated away)."""
    scene = doc.get("scene")
    return 3 if isinstance(scene, dict) and scene.get("dimension") == 2 else 6


@st.composite
def fixture_case(draw: st.DrawFn) -> tuple[bytes, int]:
    """A mutated fixture (often one that still loads) and the wrench length of its seed's dimension."""
    if draw(st.integers(0, 2)) > 0:
        doc = draw(numeric_document())
        return to_toml(doc).encode("utf-8"), ndof_of(doc)
    return draw(fixture_bytes()), 6


@st.composite
def fixture_bytes(draw: st.DrawFn, numeric_only: bool = False) -> bytes:
    """A mutated fixture file, as the bytes written to disk (``numeric_only``: numbers changed, UTF-8)."""
    if numeric_only:
        return to_toml(draw(numeric_document())).encode("utf-8")
    text = to_toml(draw(st.one_of(mutated_document(), numeric_document())))
    how = draw(st.sampled_from(BYTE_MUTATIONS))
    if how == "utf16":
        return text.encode("utf-16")
    if how == "latin1":
        return ("# café\n" + text).encode("latin-1", "replace")
    data = text.encode("utf-8", "surrogatepass")
    at = draw(st.integers(0, max(len(data) - 1, 0)))
    if how == "invalid":
        return data[:at] + b"\xff\xfe" + data[at:]
    if how == "nul":
        return data[:at] + b"\0" + data[at:]
    if how == "truncate":
        return data[:at]
    if how == "bom":
        return b"\xef\xbb\xbf" + data
    if how == "hdf5":
        return b"\x89HDF\r\n\x1a\n" + data
    if how == "crlf":
        return data.replace(b"\n", b"\r\n")
    return data


# -- command lines -----------------------------------------------------------------------------
NUMBER_TEXTS = [
    "0", "1", "-1", "1e-300", "1e300", "1e308", "1e400", "nan", "inf", "-inf", "", " ", "a", "1,2", "0x10",
    "1_000", "1e6", "1e7", "0.5", "-0", "5e-324",
]  # fmt: skip


@st.composite
def wrench_text(draw: st.DrawFn, ndof: int | None = None) -> str:
    """A wrench of ``ndof`` numbers (default 6 or 3): mostly moderate, sometimes at or past the range edge."""
    n = ndof if ndof is not None and draw(st.integers(0, 9)) > 0 else draw(st.sampled_from([6, 6, 3]))
    edge = st.sampled_from(["1e6", "-1e6", "1e-9", "0", "999999", "1e6.5", "2e6"])
    moderate = st.floats(-30, 30).map(lambda x: f"{x:.6g}")
    return ",".join(draw(st.one_of(moderate, moderate, moderate, edge)) for _ in range(n))


@st.composite
def number_list(draw: st.DrawFn, n: int | None = None) -> str:
    k = n if n is not None and draw(st.booleans()) else draw(st.integers(0, 8))
    parts = [
        draw(st.one_of(st.sampled_from(NUMBER_TEXTS), st.floats(-50, 50).map(lambda x: f"{x:g}"))) for _ in range(k)
    ]
    return ",".join(parts)


# -- malformed FCLib files ---------------------------------------------------------------------
def write_local_problem(path: Path, contacts: int = 2, *, rng: np.random.Generator | None = None) -> Path:
    """A valid local 3D FCLib problem (W symmetric positive definite, CSR) with ``contacts`` contacts."""
    import h5py

    rng = rng or np.random.default_rng(0)
    m = 3 * contacts
    A = rng.normal(size=(m, m))
    W = A @ A.T + m * np.eye(m)
    rows, cols = np.nonzero(W)
    indptr = np.searchsorted(rows, np.arange(m + 1)).astype(np.int32)
    with h5py.File(path, "w") as fh:
        root = fh.create_group("fclib_local")
        root["spacedim"] = np.array([3], np.int32)
        g = root.create_group("W")
        g["m"] = np.array([m], np.int32)
        g["n"] = np.array([m], np.int32)
        g["nz"] = np.array([-2], np.int32)
        g["nzmax"] = np.array([len(rows)], np.int32)
        g["p"] = indptr
        g["i"] = cols.astype(np.int32)
        g["x"] = W[rows, cols]
        vec = root.create_group("vectors")
        q = np.zeros(m)
        q[0::3] = -1.0
        vec["q"] = q
        vec["mu"] = np.full(contacts, 0.3)
    return path


FCLIB_FIELDS = ("spacedim", "W/m", "W/n", "W/nz", "W/nzmax", "W/p", "W/i", "W/x", "vectors/q", "vectors/mu")
FCLIB_REPLACEMENTS = {
    "delete": None,
    "empty": np.array([], np.int32),
    "negative": np.array([-1], np.int32),
    "huge": np.array([2**31 - 1], np.int32),
    "nan": np.array([np.nan]),
    "inf": np.array([np.inf, -np.inf]),
    "string": np.bytes_(b"oops"),
    "float-index": np.array([0.5, 1.5]),
    "matrix": np.ones((2, 2)),
    "zero": np.array([0], np.int32),
    "reversed": "reverse",
    "shuffled": "shuffle",
    "group": "group",
}


def mutate_fclib(path: Path, field: str, how: str, rng: np.random.Generator) -> None:
    """Replace (or delete, or reorder) one dataset of a valid problem written by :func:`write_local_problem`."""
    import h5py

    with h5py.File(path, "r+") as fh:
        root = fh["fclib_local"]
        old = np.asarray(root[field][()]) if field in root else None
        del root[field]
        repl = FCLIB_REPLACEMENTS[how]
        if repl is None:
            return
        if isinstance(repl, str):
            if repl == "group":
                root.create_group(field)
                return
            assert old is not None
            new = old[::-1].copy() if repl == "reverse" else rng.permutation(old.reshape(-1))
            if new.size and np.issubdtype(new.dtype, np.integer) and repl == "shuffle":
                new = new + rng.integers(-3, 4, size=new.shape).astype(new.dtype)
            root[field] = new
            return
        root[field] = repl


# -- hostile HDF5 files: links, corruption, oversized declarations ------------------------------
FCLIB_PATHS = (
    "fclib_local",
    "fclib_local/W",
    "fclib_local/vectors",
    "fclib_local/spacedim",
    *(f"fclib_local/{field}" for field in FCLIB_FIELDS),
)


@st.composite
def fclib_link(draw: st.DrawFn) -> tuple[str, str, str]:
    """``(where, kind, target)``: a link replacing one node of a valid problem (or added beside it).

    ``kind``: ``soft`` (to a missing node, to itself, to another node, to an ancestor),
    ``external`` (to ``/etc/passwd``, to a missing file, to a valid FCLib file, to this file), or
    ``hard-cycle`` (a group linked into itself).
    """
    where = draw(st.sampled_from((*FCLIB_PATHS, "solution/r", "guesses")))
    kind = draw(st.sampled_from(("soft", "external", "hard-cycle")))
    if kind == "soft":
        target = draw(st.sampled_from(("/nowhere", "/" + where, "/fclib_local", "/fclib_local/vectors/q", "/")))
    elif kind == "external":
        target = draw(st.sampled_from(("/etc/passwd", "missing.hdf5", "valid.hdf5", "self")))
    else:
        target = draw(st.sampled_from(("/", "/fclib_local", "/fclib_local/W")))
    return where, kind, target


def link_fclib(path: Path, where: str, kind: str, target: str) -> None:
    """Apply :func:`fclib_link`'s draw to a valid problem at ``path`` (``valid.hdf5`` is written beside it)."""
    import h5py

    if target == "valid.hdf5":
        write_local_problem(path.with_name("valid.hdf5"))
    with h5py.File(path, "r+") as fh:
        if kind == "hard-cycle":
            group = fh.require_group(where if where in fh and isinstance(fh[where], h5py.Group) else "guesses")
            group["cycle"] = fh[target]
            return
        if where in fh:
            del fh[where]
        elif "/" in where:
            fh.require_group(where.rsplit("/", 1)[0])
        if kind == "soft":
            fh[where] = h5py.SoftLink(target)
        else:
            filename = {"self": str(path), "valid.hdf5": str(path.with_name("valid.hdf5"))}.get(target, target)
            fh[where] = h5py.ExternalLink(filename, "/" + where if target != "/etc/passwd" else "/x")


@st.composite
def corruption(draw: st.DrawFn) -> list[tuple[str, float, int]]:
    """Edits of a file's bytes: ``(how, where as a fraction of the length, value)``.

    ``flip`` xors one byte; ``burst`` overwrites 1–64 bytes with a repeated value; ``truncate``
    cuts the file. Most draws aim at the first 4 KiB, where HDF5 keeps its superblock and the
    headers of the root group.
    """
    edits = st.tuples(
        st.sampled_from(("flip", "flip", "burst", "truncate")),
        st.one_of(st.floats(0.0, 0.05), st.floats(0.0, 1.0)),
        st.integers(1, 255),
    )
    return draw(st.lists(edits, min_size=1, max_size=6))


def corrupt_bytes(data: bytes, edits: list[tuple[str, float, int]]) -> bytes:
    """Apply :func:`corruption`'s edits in order."""
    out = bytearray(data)
    for how, where, value in edits:
        if not out:
            break
        at = min(int(where * len(out)), len(out) - 1)
        if how == "flip":
            out[at] ^= value
        elif how == "burst":
            size = 1 + value % 64
            out[at : at + size] = bytes([value]) * len(out[at : at + size])
        else:
            del out[at:]
    return bytes(out)


@st.composite
def oversized(draw: st.DrawFn) -> tuple[str, int, int | None, bool]:
    """``(dataset, declared entries, chunk entries or None, gzip)``: a dataset declaring far more than it stores."""
    field = draw(st.sampled_from(FCLIB_FIELDS))
    entries = 10 ** draw(st.integers(6, 12))
    chunk = draw(st.sampled_from((None, 1, 1000, 10**6)))
    return field, entries, chunk, draw(st.booleans())


def oversize_fclib(path: Path, field: str, entries: int, chunk: int | None, gzip: bool) -> None:
    """Replace ``fclib_local/<field>`` by an unwritten dataset of ``entries`` entries (chunked, or contiguous)."""
    import h5py

    with h5py.File(path, "r+") as fh:
        root = fh["fclib_local"]
        dtype = "f8" if field in ("W/x", "vectors/q", "vectors/mu") else "i4"
        del root[field]
        if chunk is None:  # contiguous: the space is declared and never allocated (reading it gives fill values)
            root.create_dataset(field, shape=(entries,), dtype=dtype)
        else:
            root.create_dataset(
                field,
                shape=(entries,),
                dtype=dtype,
                chunks=(min(chunk, entries),),
                compression="gzip" if gzip else None,
            )
