"""Deeply nested TOML is refused before parsing, in one linear scan.

A fixture with one dotted key nested 40,000 deep (82 KB) took over 120 s to validate: tomllib's
cost grows with the square of the depth, so the 1 MiB size limit did not bound the work. Every
form of nesting is counted: dotted keys, table headers ``[a.a.a]`` and ``[[a.a.a]]``, arrays
``[[[…]]]``, inline tables ``{a={a=…}}`` and dotted keys inside inline tables.
"""

from __future__ import annotations

import tomllib

import pytest
from conftest import PROBLEMS, ROOT, run_cli

import fixplan
from fixplan.errors import FixtureError
from fixplan.limits import MAX_TOML_NESTING, toml_nesting

BASE = (PROBLEMS / "box-3-2-1.toml").read_text()
N = 40_000


def _deep(form: str, n: int) -> str:
    """The box-3-2-1 fixture with one construct nested ``n`` deep, in the given form."""
    key = ".".join(["a"] * n)
    return {
        "dotted": BASE + f"\n[extra]\n{key} = 1\n",
        "top-dotted": f"{key} = 1\n" + BASE,
        "header": BASE + f"\n[{key}]\nx = 1\n",
        "array-header": BASE + f"\n[[{key}]]\nx = 1\n",
        "array": BASE.replace("format = 1", "format = 1\nx = " + "[" * n + "]" * n),
        "inline": BASE.replace("format = 1", "format = 1\nx = " + "{a=" * n + "1" + "}" * n),
        "inline-dotted": BASE.replace("format = 1", "format = 1\nx = {" + key + " = 1}"),
        "mixed": BASE.replace("format = 1", "format = 1\nx = " + "{a.a=[" * (n // 3) + "]}" * (n // 3)),
    }[form]


def _levels(doc: dict) -> int:
    """Levels of tables and arrays under a parsed TOML document's root."""
    return _depth(doc) - 1


def _depth(value: object) -> int:
    """Levels of tables and arrays in a parsed TOML value (a scalar: 0)."""
    if isinstance(value, dict):
        return 1 + max((_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    return 0


FORMS = ["dotted", "top-dotted", "header", "array-header", "array", "inline", "inline-dotted", "mixed"]


@pytest.mark.parametrize("form", FORMS)
def test_forty_thousand_levels_are_refused_at_once(tmp_path, form):
    """Exit 2, one line naming the line of the file and the limit (a hang check: 120 s before the fix)."""
    path = tmp_path / "deep.toml"
    text = _deep(form, N)
    path.write_text(text)
    proc = run_cli("validate", str(path), timeout=60, cwd=ROOT)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2, proc.stderr[-500:]
    assert len(lines) == 1, proc.stderr[-500:]
    assert f"expected at most {MAX_TOML_NESTING} levels" in lines[0]
    # the line named is the one holding the deep construct
    line_no = int(lines[0].split("line ")[1].split(":")[0])
    assert (
        "a.a" in text.splitlines()[line_no - 1]
        or "[[" in text.splitlines()[line_no - 1]
        or "{a" in text.splitlines()[line_no - 1]
    )


@pytest.mark.parametrize("form", FORMS)
def test_the_limit_holds_near_the_boundary(form):
    """Nesting below the limit parses; the scan never refuses what tomllib builds shallower than the limit."""
    for n in (3, MAX_TOML_NESTING // 2):
        text = _deep(form, n)
        assert toml_nesting(text) is None
        assert _levels(tomllib.loads(text)) <= MAX_TOML_NESTING
    text = _deep(form, MAX_TOML_NESTING + 1)
    found = toml_nesting(text)
    assert found is not None and found[1] > MAX_TOML_NESTING
    with pytest.raises(FixtureError, match="nested .* deep"):
        fixplan.loads(text)


@pytest.mark.parametrize(
    ("text", "depth"),
    [
        ("a.b.c = 1\n", 3),  # three tables: a, b, c
        ("a.b = {c.d = [[1]]}\n", 5),  # a, b, c, d and the inner array
        ("x = [[[1]]]\n", 3),
        ("x = {y = {z = 1}}\n", 2),
        ("[t]\na.b = 1\n", 3),  # t, a, b
        ("[[t.u]]\nv = [[1]]\n", 5),  # t, u (an array), its table, v, the inner array
        ("[t.u.v]\n[w]\nx = 1\n", 3),  # a new header starts again from the root
    ],
)
def test_depth_counts_every_level(text, depth):
    assert toml_nesting(text, limit=depth) is None
    assert toml_nesting(text, limit=depth - 1) is not None


@pytest.mark.parametrize(
    "text",
    [
        'x = "' + "a." * 100 + '"\n',  # dots in a string
        "x = '" + "[" * 100 + "'\n",  # brackets in a literal string
        'x = """\n' + "{" * 100 + '\n"""\n',  # ... in a multi-line string
        "x = '''\n" + "a." * 100 + "\n'''\n",
        "# " + "[" * 100 + "\n",  # in a comment
        'x = "\\"' + "[" * 100 + '"\n',  # after an escaped quote
        "x = [" + ", ".join(["1.5"] * 1000) + "]\n",  # many numbers with dots, one level
        '"a.b.c.d.e.f.g.h.i.j.k.l.m.n.o.p.q.r.s.t.u.v.w.x.y.z.A.B.C.D.E.F.G.H.I.J" = 1\n',  # one quoted key
    ],
)
def test_strings_comments_and_numbers_do_not_count(text):
    assert toml_nesting(text) is None
    tomllib.loads(text)  # and they are valid TOML


def test_every_bundled_fixture_nests_at_most_four():
    files = [*PROBLEMS.glob("*.toml"), fixplan.default_fixture_path()]
    assert len(files) > 10
    for path in files:
        text = path.read_text()
        assert toml_nesting(text, limit=4) is None, path
        assert _levels(tomllib.loads(text)) <= 4


def test_the_error_names_the_line():
    text = BASE + "\n[extra]\n" + ".".join(["k"] * 100) + " = 1\n"
    with pytest.raises(FixtureError) as err:
        fixplan.loads(text, "deep.toml")
    line = len(BASE.splitlines()) + 3
    assert f"<toml>: line {line}: tables, arrays or dotted keys nested" in str(err.value)


def test_docs_state_the_limit():
    doc = (ROOT / "docs" / "limits.md").read_text(encoding="utf-8")
    assert f"| {MAX_TOML_NESTING} levels |" in doc
