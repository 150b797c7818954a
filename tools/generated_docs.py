"""What the doc generators in tools/ share: a table spliced between markers, and ``--write``/``--check``."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def splice(doc: Path, begin: str, end: str, body: str) -> str:
    """``doc``'s text with ``body`` between the markers ``begin`` and ``end`` (both kept)."""
    head, rest = doc.read_text(encoding="utf-8").split(begin)
    tail = rest.split(end, 1)[1]
    return head + begin + body + end + tail


def main(expected: Callable[[], dict[Path, str]], script: str, description: str, what: str) -> int:
    """``--write`` the generated ``what``, or ``--check`` it (exit 1 when stale); ``script`` names the tool."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--write", action="store_true", help=f"rewrite the generated {what}")
    parser.add_argument("--check", action="store_true", help=f"exit 1 when the generated {what} is stale")
    args = parser.parse_args()
    texts = expected()
    stale = [p for p, text in texts.items() if p.read_text(encoding="utf-8") != text]
    if args.write:
        for path, text in texts.items():
            path.write_text(text, encoding="utf-8")
            print(f"wrote {path.relative_to(ROOT)}")
        return 0
    for path in stale:
        print(f"{path.relative_to(ROOT)} is stale: run python tools/{script} --write")
    return 1 if stale and args.check else 0
