"""The fixture format's generated docs: the JSON Schema and the key reference, from the declarations.

``python tools/fixture_docs.py --write`` rewrites ``docs/fixture.schema.json`` (what ``fixplan
schema`` prints) and the key table between the markers in ``docs/fixture-format.md`` (from
``fixplan.fixture_schema.markdown_reference``); ``--check`` exits 1 when either is stale.
``tests/test_fixture_schema.py`` runs the same comparison. Run it after declaring a key or a table.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from generated_docs import main, splice  # noqa: E402

from fixplan.fixture_schema import markdown_reference, schema_text  # noqa: E402

SCHEMA = ROOT / "docs" / "fixture.schema.json"
DOC = ROOT / "docs" / "fixture-format.md"
BEGIN, END = "<!-- keys:begin -->\n", "<!-- keys:end -->"


def expected() -> dict[Path, str]:
    """Each generated file's text as the declarations give it."""
    return {SCHEMA: schema_text(), DOC: splice(DOC, BEGIN, END, markdown_reference())}


if __name__ == "__main__":
    sys.exit(main(expected, "fixture_docs.py", __doc__.splitlines()[0], "files"))
