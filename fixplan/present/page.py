"""The scene as one self-contained HTML page: plotly.js embedded, nothing fetched when it is opened."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from fixplan.errors import FixplanError
from fixplan.files import write_text

_EXTERNAL = re.compile(r"""<(?:script|link|img|iframe)\b[^>]*\b(?:src|href)\s*=\s*["']?\s*(?:https?:)?//""", re.I)


def external_references(html: str) -> list[str]:
    """Tags of ``html`` that would load something from the network (script/link/img/iframe src or href)."""
    return [m.group(0) for m in _EXTERNAL.finditer(html)]


def write_scene(fig: Any, path: Path) -> int:
    """Write ``fig`` as a self-contained HTML page (plotly.js embedded, no MathJax); return its size [bytes].

    Raises
    ------
    FixplanError
        The page would fetch something (a bug: every script is embedded).
    """
    html = fig.to_html(
        include_plotlyjs=True,
        include_mathjax=False,
        full_html=True,
        auto_play=False,
        config={"displaylogo": False, "responsive": True},
    )
    refs = external_references(html)
    if refs:
        raise FixplanError(f"the page would fetch {refs[0]!r}: refusing to write {path}")
    write_text(Path(path), html)
    return len(html.encode("utf-8"))
