"""The fixture format's generated docs: the JSON Schema and the key reference, from the declarations.

``python tools/fixture_docs.py --write`` rewrites ``docs/fixture.schema.json`` (what ``fixplan
schema`` prints) and the key table between the markers in ``docs/fixture-format.md`` (from
``fixplan.fixture_schema.markdown_reference``); ``--check`` exits 1 when either is stale.
``tests/test_fixture_schema.py`` runs the same comparison. Run it after declaring a key or a table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fixplan.fixture_schema import markdown_reference, schema_text  # noqa: E402

SCHEMA = ROOT / "docs" / "fixture.schema.json"
DOC = ROOT / "docs" / "fixture-format.md"
BEGIN, END = "<!-- keys:begin -->\n", "<!-- keys:end -->"


def expected() -> dict[Path, str]:
    """Each generated file's text as the declarations give it."""
    doc = DOC.read_text(encoding="utf-8")
    head, rest = doc.split(BEGIN)
    tail = rest.split(END, 1)[1]
    return {SCHEMA: schema_text(), DOC: head + BEGIN + markdown_reference() + END + tail}


def main() -> int:
    """``--write`` the generated files, or ``--check`` them (exit 1 when stale)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the generated files")
    parser.add_argument("--check", action="store_true", help="exit 1 when a generated file is stale")
    args = parser.parse_args()
    stale = [p for p, text in expected().items() if p.read_text(encoding="utf-8") != text]
    if args.write:
        for path, text in expected().items():
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path.relative_to(ROOT)}")
        return 0
    for path in stale:
        print(f"{path.relative_to(ROOT)} is stale: run python tools/fixture_docs.py --write")
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
