"""The UDP bridge's message table in docs/haptic.md, generated from the code's ``struct`` formats.

``python tools/protocol_docs.py --write`` rewrites the table between the markers in
``docs/haptic.md`` from :func:`fixplan.interactive.protocol.markdown_table` (layouts, fields and the
sizes ``struct`` computes); ``--check`` exits 1 when it is stale. ``tests/test_protocol_docs.py``
runs the same comparison, so a client built from the docs gets the sizes the code sends and expects.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from generated_docs import main, splice  # noqa: E402

from fixplan.interactive.protocol import markdown_table  # noqa: E402

DOC = ROOT / "docs" / "haptic.md"
BEGIN, END = "<!-- udp-messages:begin -->\n", "<!-- udp-messages:end -->"


def expected() -> dict[Path, str]:
    """Each generated file's text as the code gives it."""
    return {DOC: splice(DOC, BEGIN, END, markdown_table())}


if __name__ == "__main__":
    sys.exit(main(expected, "protocol_docs.py", __doc__.splitlines()[0], "table"))
