"""Expected-verdict tables (``problems/expected.toml``): read and checked like fixture files.

A table holds ``[[case]]`` entries (``file``, ``pose``, ``contacts``, ``wrench``, ``mode``,
``why``), ``[[wedge]]`` entries (``file``, ``wedges``, ``why``) and ``[[touching]]`` entries
(``file``, ``names``), and ``[[plan]]`` entries (``file``, ``status`` planned | infeasible,
``verified``, ``first``/``last`` states, ``sequence``, ``binding`` limit named in the reason,
``why``, and ``xfail_reason`` where the planner disagrees with the derived outcome: the tests
mark it as an expected failure) for ``fixplan solve``, and ``[[clamp]]`` entries (``file``,
``holds``, the clamping ``order`` found, a ``refused_order`` and words its reason holds,
``because``, ``why``) for ``fixplan clamp``. ``fixplan validate`` recognises such a
file (it has ``case`` entries and no ``format`` key) and checks that every referenced fixture
exists and loads, that wrenches have the fixture's length, that modes and poses are known and
that contact names exist. An entry whose fixture names a robot of example-robot-data is not
checked where that optional extra (``fixplan[robots]``) is not installed; the counts say how many.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fixplan.errors import FixtureError, Issue
from fixplan.schema import Reader

KINDS = {
    "case": ("file", "pose", "contacts", "wrench", "mode", "why"),
    "wedge": ("file", "wedges", "why"),
    "touching": ("file", "names"),
    "plan": ("file", "status", "verified", "first", "last", "sequence", "binding", "why", "xfail_reason"),
    "clamp": ("file", "holds", "order", "refused_order", "because", "why"),
}


def looks_like_expectations(data: dict[str, Any]) -> bool:
    """An expected-verdict table rather than a fixture file."""
    return "format" not in data and any(k in data for k in KINDS)


def check_expectations(path: Path, data: dict[str, Any]) -> tuple[list[Issue], dict[str, int]]:
    """Every problem of an expected-verdict table, and how many entries of each kind it has."""
    from fixplan.fixture import load
    from fixplan.jamming.classify import MODES
    from fixplan.robot_file import EXTRA, names_robot_data, robot_data_installed

    have_robot_data = robot_data_installed()
    skipped: set[str] = set()  # fixtures that name a robot of the extra while it is not installed
    unchecked = 0

    r = Reader()
    r.unknown_keys(data, KINDS, "")
    cache: dict[str, Any] = {}
    counts = {}
    for kind, keys in KINDS.items():
        entries = r.tables(data, kind, kind)
        counts[kind] = len(entries)
        for i, entry in enumerate(entries):
            where = f"{kind}[{i}]"
            r.unknown_keys(entry, keys, where)
            name = r.string(entry, "file", f"{where}.file", required=True)
            if name is None:
                continue
            if name not in cache:
                target = path.parent / name
                if not have_robot_data and names_robot_data(target) is not None:
                    cache[name] = None  # it names a robot of the extra, which is not here: not checked
                    skipped.add(name)
                else:
                    try:
                        cache[name] = load(target)
                    except FixtureError as exc:
                        cache[name] = None
                        r.error(f"{where}.file", f"{name} does not load ({exc.issues[0].key}: {exc.issues[0].message})")
            fixture = cache[name]
            if fixture is None:
                unchecked += name in skipped
                continue
            if kind == "case":
                r.vector(
                    entry, "wrench", f"{where}.wrench", fixture.ndof, required=True, dimension_hint=fixture.dimension
                )
                r.string(entry, "mode", f"{where}.mode", required=True, choices=MODES)
                pose = r.string(entry, "pose", f"{where}.pose", choices=("start", "goal"))
                if pose == "goal" and not fixture.is_full:
                    r.error(f"{where}.pose", f"{name} is not a full fixture (expected pose 'start')")
                r.string(entry, "why", f"{where}.why", required=True)
                _names(r, entry, "contacts", f"{where}.contacts", fixture.names)
            elif kind == "wedge":
                if not isinstance(entry.get("wedges"), bool):
                    r.error(f"{where}.wedges", "expected true or false")
                r.string(entry, "why", f"{where}.why", required=True)
            elif kind == "clamp":
                clamps = [k.name for k in fixture.clamps]
                if not clamps:
                    r.error(f"{where}.file", f"{name} has no [[clamp]] entries (expected a clamped fixture)")
                if not isinstance(entry.get("holds"), bool):
                    r.error(f"{where}.holds", "expected true or false")
                for key in ("order", "refused_order"):
                    _names(r, entry, key, f"{where}.{key}", clamps)
                r.string(entry, "because", f"{where}.because")
                r.string(entry, "why", f"{where}.why", required=True)
            elif kind == "touching":
                _names(r, entry, "names", f"{where}.names", [loc.name for loc in fixture.locators], required=True)
            else:
                # a plan's states hold locators, pins engaged in their holes, and a bore's wall and
                # bottom ("B1", "B1.bottom") for a part loaded into a bore (the bore locates it)
                bores = [b.name for b in fixture.bores]
                locs = [loc.name for loc in fixture.locators] + [p.name for p in fixture.pins]
                locs += bores + [f"{b}.bottom" for b in bores]
                if not (fixture.is_full or bores):
                    r.error(f"{where}.file", f"{name} is not a full fixture (expected one that can be planned)")
                status = r.string(entry, "status", f"{where}.status", required=True, choices=("planned", "infeasible"))
                if "verified" in entry and not isinstance(entry["verified"], bool):
                    r.error(f"{where}.verified", "expected true or false")
                if status == "infeasible" and entry.get("verified"):
                    r.error(f"{where}.verified", "an infeasible plan cannot be verified (expected false or absent)")
                for key in ("first", "last"):
                    _names(r, entry, key, f"{where}.{key}", locs)
                seq = entry.get("sequence")
                if seq is not None:
                    if not isinstance(seq, list) or not seq:
                        r.error(f"{where}.sequence", "expected a list of states (lists of names)")
                    else:
                        for j, state in enumerate(seq):
                            _names(r, {"s": state}, "s", f"{where}.sequence[{j}]", locs, required=True)
                r.string(entry, "binding", f"{where}.binding", choices=("max_force", "max_torque"))
                r.string(entry, "why", f"{where}.why", required=True)
                r.string(entry, "xfail_reason", f"{where}.xfail_reason")
    if unchecked:
        counts[f"not checked (their robot needs example-robot-data: {EXTRA})"] = unchecked
    return r.issues, counts


def _names(r: Reader, entry: dict, key: str, path: str, known: list[str], required: bool = False) -> None:
    if key not in entry:
        if required:
            r.error(path, "missing (expected a list of names)")
        return
    value = entry[key]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        r.error(path, "expected a list of names")
        return
    for v in value:
        if v not in known:
            r.error(path, f"unknown name {v!r} (known: {', '.join(known)})")


def read_toml(path: Path) -> dict[str, Any] | None:
    """The parsed document, or None when it cannot be read or parsed (the loader says why)."""
    from fixplan.fixture import parse_toml, read_fixture_text

    try:
        return parse_toml(read_fixture_text(path), str(path))
    except FixtureError:
        return None
