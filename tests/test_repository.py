"""The repository stands on its own: no reference points outside it.

A user's clone has no ``../shared`` folder beside it and no access to the tracker the project
was built with, so the docs, code, tests, notebooks and problem files cite ``docs/math.md`` and
``docs/fixture-format.md`` and say the thing itself instead of "issue 4 §6". Allowed: the tests
that skip without ``../shared`` data and the benchmarks that read it (they name the folder they
look in), and ``CHANGELOG.md``, the project's history.
"""

from __future__ import annotations

import re

from conftest import ROOT

SKIP_DIRS = {".git", ".venv", "__pycache__", "build", "dist", ".mypy_cache", ".ruff_cache", ".pytest_cache"}
HISTORY = {"CHANGELOG.md"}
READS_SHARED_DATA = {
    "tests/conftest.py",
    "tests/engine/test_fclib_bounds.py",
    "tests/engine/test_residual.py",
    "benchmarks/bench_fclib.py",
    "benchmarks/behaviour.py",
}
SHARED = re.compile(r"\.\./" + "shared|shared/" + "spec")
TRACKER = re.compile(r"\bissues? #?\d+|\bissue's\b|§ ?\d", re.IGNORECASE)
OLD_SPEC = re.compile(r"\b(?:MATH|FIXTURE_FORMAT)\.md")  # now docs/math.md, docs/fixture-format.md


def _texts() -> list[tuple[str, str]]:
    out = []
    for path in sorted(ROOT.rglob("*")):
        rel = path.relative_to(ROOT)
        if not path.is_file() or any(part in SKIP_DIRS or part.endswith(".egg-info") for part in rel.parts):
            continue
        data = path.read_bytes()
        if b"\0" in data or len(data) > 2_000_000:
            continue  # binary (HDF5, images, numba caches) or generated data
        out.append((rel.as_posix(), data.decode("utf-8", errors="replace")))
    return out


def test_the_docs_the_code_cites_are_in_the_repository():
    for name in ("docs/math.md", "docs/fixture-format.md"):
        text = (ROOT / name).read_text(encoding="utf-8")
        assert "Contact laws" in text or "[[locator]]" in text, name
    fmt = (ROOT / "docs/fixture-format.md").read_text(encoding="utf-8")
    for key in ("format", "[scene]", "[workpiece]", "[[locator]]", "[[contact]]", "[manipulator]", "[simulation]"):
        assert key in fmt, key


def test_no_file_points_outside_the_repository():
    texts = _texts()
    assert len(texts) > 50  # the walk found the tree
    found = []
    for rel, text in texts:
        if rel in HISTORY or rel == "tests/test_repository.py":
            continue
        for n, line in enumerate(text.splitlines(), 1):
            if TRACKER.search(line) or OLD_SPEC.search(line) or (SHARED.search(line) and rel not in READS_SHARED_DATA):
                found.append(f"{rel}:{n}: {line.strip()[:100]}")
    assert not found, "references outside the repository:\n" + "\n".join(found)


def test_no_file_carries_merge_conflict_markers():
    """A merge left ``<<<<<<< HEAD`` … ``>>>>>>>`` in docs/architecture.md once, committed and unseen."""
    marker = re.compile(r"^(?:<{7} |>{7} |={7}$)", re.MULTILINE)
    found = [name for name, text in _texts() if marker.search(text)]
    assert found == []
