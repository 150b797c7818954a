"""The fixture format's declarations (``fixplan/fixture_schema.py``) against their JSON Schema and docs.

The schema shipped in ``docs/fixture.schema.json`` is what ``fixplan schema`` prints; every key
the format page shows is declared and every declared key is on the page; every problem file
validates against the JSON Schema; and on a seeded corpus of one-key mutations of the problem
files the JSON Schema refuses a file exactly when the declarations do (except what JSON Schema
cannot say: a convex polygon, ``nan``), so an editor's checks and ``fixplan validate`` agree.
"""

from __future__ import annotations

import copy
import json
import math
import re
import tomllib
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from conftest import PROBLEMS, ROOT

import fixplan
from fixplan.cli import main
from fixplan.errors import FixtureError
from fixplan.fixture import _dimension_of, _shape_of, default_fixture_path
from fixplan.fixture_schema import (
    FixtureFile,
    json_schema,
    markdown_reference,
    schema_keys,
    schema_text,
    validate_document,
)

DOCS = ROOT / "docs" / "fixture-format.md"
SHIPPED = ROOT / "docs" / "fixture.schema.json"
FIXTURES = sorted(p for p in PROBLEMS.glob("*.toml") if p.name != "expected.toml") + [default_fixture_path()]
VALIDATOR = jsonschema.Draft7Validator(json_schema())


def _schema_errors(doc: dict) -> list[str]:
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in VALIDATOR.iter_errors(doc)]


def _declared_issues(doc: dict) -> list[str]:
    dim = _dimension_of(doc)
    _, issues = validate_document(doc, dim, _shape_of(doc, dim))
    return [f"{i.key}: {i.message}" for i in issues] or (["scene.dimension"] if dim is None else [])


# -- the shipped schema, the command, the docs -----------------------------------------------------
def test_the_shipped_schema_is_what_fixplan_schema_prints(capsys) -> None:
    assert main(["schema"]) == 0
    printed = capsys.readouterr().out
    assert printed == schema_text() == SHIPPED.read_text(encoding="utf-8"), (
        "docs/fixture.schema.json is stale: run python tools/fixture_docs.py --write"
    )
    jsonschema.Draft7Validator.check_schema(json.loads(printed))  # a valid draft-07 schema


def test_schema_out_writes_atomically_and_keeps_an_existing_file(capsys, tmp_path: Path) -> None:
    out = tmp_path / "fixture.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == schema_text()
    assert [p.name for p in tmp_path.iterdir()] == [out.name]  # no temporary file left beside it
    out.write_text("{}")
    assert main(["schema", "--out", str(out)]) == 2
    assert "exists (use --force to overwrite it)" in capsys.readouterr().err
    assert out.read_text() == "{}"
    assert main(["schema", "--out", str(out), "--force"]) == 0
    assert out.read_text(encoding="utf-8") == schema_text()


def test_the_key_reference_in_the_docs_is_drawn_from_the_declarations() -> None:
    text = DOCS.read_text(encoding="utf-8")
    table = text.split("<!-- keys:begin -->\n")[1].split("<!-- keys:end -->")[0]
    assert table == markdown_reference(), "the key table is stale: run python tools/fixture_docs.py --write"
    listed = re.findall(r"^\| `([\w.]+)` \|", table, flags=re.MULTILINE)
    assert listed == schema_keys() and len(listed) == len(set(listed)) >= 40


def _example_keys() -> dict[str, set[str]]:
    """The keys the format page's example file shows (comments included), by top-level table."""
    block = DOCS.read_text(encoding="utf-8").split("```toml\n")[1].split("```")[0]
    keys: dict[str, set[str]] = {"": set()}
    table = ""
    for line in block.splitlines():
        header = re.match(r"^\[\[?(\w+)\]\]?", line)
        if header:
            table = header.group(1)
            keys.setdefault(table, set())
            continue
        # a key stands at the start of a line or comment, in an inline table, or after "shape:" in a comment
        keys[table] |= set(re.findall(r"(?:^|[#{,:;])\s*([A-Za-z_]\w*)\s*=\s", line))
    return keys


def _declared_keys() -> dict[str, set[str]]:
    tables = {key.partition(".")[0] for key in schema_keys() if "." in key}
    out: dict[str, set[str]] = {"": {key for key in schema_keys() if "." not in key} - tables}  # tables have headers
    for key in schema_keys():
        top, _, rest = key.partition(".")
        if rest:
            out.setdefault(top, set()).update(rest.split("."))
    return out


def test_every_key_the_format_page_shows_is_declared_and_the_reverse() -> None:
    shown, declared = _example_keys(), _declared_keys()
    assert shown == declared, {
        t: {"shown, not declared": shown.get(t, set()) - declared.get(t, set()),
            "declared, not shown": declared.get(t, set()) - shown.get(t, set())}
        for t in set(shown) | set(declared) if shown.get(t) != declared.get(t)
    }  # fmt: skip
    assert {"scene", "workpiece", "locator", "contact", "manipulator", "simulation"} <= set(shown)
    assert {"radius", "length", "vertices", "file", "inertia", "angle_deg", "rpy_deg"} <= shown["workpiece"]


def test_every_number_declares_its_range_and_every_length_its_unit() -> None:
    def leaves(node: dict, path: str):  # type: ignore[no-untyped-def]
        for key, sub in node.get("properties", {}).items():
            yield f"{path}.{key}".strip("."), sub

    schema = json_schema()
    defs = schema["definitions"]
    numbers = []
    for name, table in [("", schema), *defs.items()]:
        for path, sub in leaves(table, name):
            element = sub.get("items", sub)
            if element.get("type") == "number":
                numbers.append(path)
                has_low = "minimum" in element or "exclusiveMinimum" in element
                assert has_low or path == "Contact.normal", f"{path}: no lower bound"
                assert "maximum" in element or path == "Contact.normal", f"{path}: no upper bound"
    assert len(numbers) >= 20
    for path in ("Workpiece.size", "Workpiece.radius", "Locator.position", "Pose.position", "Scene.gravity"):
        table, key = path.split(".")
        assert defs[table]["properties"][key]["x-unit"] in ("m", "m/s²"), path
    assert defs["Workpiece"]["properties"]["mass"]["x-unit"] == "kg"
    assert defs["Pose"]["properties"]["rpy_deg"]["x-unit"] == "deg"


# -- files against the schema ----------------------------------------------------------------------
@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.name)
def test_every_problem_file_validates_against_the_json_schema(path: Path) -> None:
    doc = tomllib.loads(path.read_text(encoding="utf-8"))
    assert _schema_errors(doc) == []
    assert _declared_issues(doc) == []
    assert isinstance(FixtureFile.model_validate(doc, context={"dimension": _dimension_of(doc)}), FixtureFile)


BOX = tomllib.loads((PROBLEMS / "box-3-2-1.toml").read_text(encoding="utf-8"))
PLATE = tomllib.loads((PROBLEMS / "rect-3.toml").read_text(encoding="utf-8"))


def _edit(doc: dict, path: tuple, value: object = None, *, delete: bool = False) -> dict:
    out = copy.deepcopy(doc)
    node = out
    for part in path[:-1]:
        node = node[part]
    if delete:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return out


HOSTILE = [  # (name, document, the key fixplan names, the schema path that fails)
    ("size in mm", _edit(BOX, ("workpiece", "size"), [300, 200, 80]), "workpiece.size[0]", "workpiece/size/0"),
    ("negative mass", _edit(BOX, ("workpiece", "mass"), -1.0), "workpiece.mass", "workpiece/mass"),
    ("friction as text", _edit(BOX, ("locator", 0, "friction"), "high"), "locator.B1.friction", "locator/0/friction"),
    ("unknown key", _edit(BOX, ("scene", "colour"), "red"), "scene.colour", "scene"),
    ("no format", _edit(BOX, ("format",), delete=True), "format", ""),
    ("format 2", _edit(BOX, ("format",), 2), "format", "format"),
    ("2D shape in 3D", _edit(BOX, ("workpiece", "shape"), "disk"), "workpiece.shape", "workpiece/shape"),
    ("radius on a box", _edit(BOX, ("workpiece", "radius"), 0.1), "workpiece.radius", "workpiece"),
    ("2D vector in 3D", _edit(BOX, ("locator", 1, "position"), [0.1, 0.2]), "locator.B2.position", "locator/1/position"),
    ("angle_deg in 3D", _edit(BOX, ("workpiece", "start", "angle_deg"), 4.0), "workpiece.start.angle_deg", "workpiece/start"),
    ("torsion in 2D", _edit(PLATE, ("locator", 0, "torsion"), 0.01), "locator.", "locator/0"),
    ("bad name", _edit(BOX, ("locator", 0, "name"), "B 1"), "locator[0].name", "locator/0/name"),
    ("locators not tables", _edit(BOX, ("locator",), [1, 2]), "locator", "locator/0"),
    ("huge gravity", _edit(BOX, ("scene", "gravity"), [0.0, 0.0, -1e9]), "scene.gravity[2]", "scene/gravity/2"),
    ("zero timestep", _edit(BOX, ("simulation",), {"timestep": 0.0}), "simulation.timestep", "simulation/timestep"),
]  # fmt: skip


@pytest.mark.parametrize(("name", "doc", "key", "where"), HOSTILE, ids=[h[0] for h in HOSTILE])
def test_hostile_files_are_refused_by_fixplan_and_by_the_schema(name, doc, key, where, tmp_path: Path) -> None:
    path = tmp_path / "f.json"
    with pytest.raises(FixtureError) as info:
        fixplan.fixture.loads(_toml(doc), source=str(path))
    assert any(issue.key.startswith(key) for issue in info.value.issues), info.value.issues
    errors = _schema_errors(doc)
    assert errors, f"{name}: the JSON Schema accepts it"
    assert any(e.startswith(f"{where}:") or (where == "" and e.startswith(":")) for e in errors), errors


def _toml(doc: dict) -> str:
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "fuzz"))
    from mutations import to_toml

    return to_toml(doc)


# -- the declarations and the JSON Schema agree ---------------------------------------------------
VALUES = ["x", "", -1, 0, 0.5, 2, 300, 1e300, 10**400, float("inf"), True, [], [1.0], [1, 2, 3, 4], ["a", 1e9, -5],
          {}, {"q": 1}, [{"a": 1}], 3]  # fmt: skip


def _leaves(node: object, prefix: tuple = ()) -> list[tuple]:
    if isinstance(node, dict):
        return [prefix + (k,) for k in node] + [p for k, v in node.items() for p in _leaves(v, prefix + (k,))]
    if isinstance(node, list):
        return [prefix + (i,) for i in range(len(node))] + [
            p for i, v in enumerate(node) for p in _leaves(v, prefix + (i,))
        ]
    return []


def _mutations(count: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    seeds = [tomllib.loads(p.read_text(encoding="utf-8")) for p in FIXTURES]
    out = []
    while len(out) < count:
        doc = seeds[rng.integers(len(seeds))]
        path = _leaves(doc)[rng.integers(len(_leaves(doc)))]
        choice = int(rng.integers(len(VALUES) + 2))
        if choice == len(VALUES):
            mutated = _edit(doc, path, delete=True)
        elif choice == len(VALUES) + 1:
            if not isinstance(path[-1], str):  # an element of a list: no key to add beside it
                continue
            mutated = _edit(doc, (*path[:-1], "zzz"), 1)  # an unknown key beside a known one
        else:
            mutated = _edit(doc, path, copy.deepcopy(VALUES[choice % len(VALUES)]))
        out.append(mutated)
    return out


def _is_polygon_geometry(issues: list[str]) -> bool:
    return all(i.startswith("workpiece.vertices:") for i in issues)


def test_the_json_schema_refuses_a_file_exactly_when_fixplan_does() -> None:
    verdicts = {"both refuse": 0, "both accept": 0}
    for doc in _mutations(600, seed=2026):
        declared, schema = _declared_issues(doc), _schema_errors(doc)
        if declared and not schema:
            assert _is_polygon_geometry(declared), f"the JSON Schema accepts what fixplan refuses: {declared}"
            continue
        assert bool(declared) == bool(schema), f"fixplan: {declared or 'ok'}; JSON Schema: {schema or 'ok'}"
        verdicts["both refuse" if declared else "both accept"] += 1
    assert verdicts["both refuse"] > 300 and verdicts["both accept"] > 50, verdicts


def test_nan_is_refused_by_fixplan_though_json_has_no_word_for_it() -> None:
    doc = _edit(BOX, ("workpiece", "mass"), math.nan)
    assert _declared_issues(doc) == ["workpiece.mass: got nan (expected a finite number)"]
