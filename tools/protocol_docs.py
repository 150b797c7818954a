"""The UDP bridge's message table in docs/haptic.md, generated from the code's ``struct`` formats.

``python tools/protocol_docs.py --write`` rewrites the table between the markers in
``docs/haptic.md`` from :func:`fixplan.interactive.protocol.markdown_table` (layouts, fields and the
sizes ``struct`` computes); ``--check`` exits 1 when it is stale. ``tests/test_protocol_docs.py``
runs the same comparison, so a client built from the docs gets the sizes the code sends and expects.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from fixplan.interactive.protocol import markdown_table  # noqa: E402

DOC = ROOT / "docs" / "haptic.md"
BEGIN, END = "<!-- udp-messages:begin -->\n", "<!-- udp-messages:end -->"


def expected() -> dict[Path, str]:
    """Each generated file's text as the code gives it."""
    doc = DOC.read_text(encoding="utf-8")
    head, rest = doc.split(BEGIN)
    tail = rest.split(END, 1)[1]
    return {DOC: head + BEGIN + markdown_table() + END + tail}


def main() -> int:
    """``--write`` the generated table, or ``--check`` it (exit 1 when stale)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the generated table")
    parser.add_argument("--check", action="store_true", help="exit 1 when the table is stale")
    args = parser.parse_args()
    stale = [p for p, text in expected().items() if p.read_text(encoding="utf-8") != text]
    if args.write:
        for path, text in expected().items():
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path.relative_to(ROOT)}")
        return 0
    for path in stale:
        print(f"{path.relative_to(ROOT)} is stale: run python tools/protocol_docs.py --write")
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main())
