"""The house keeps its plan: no import from a higher layer, no import cycle, the picture up to date.

The rules and the layers are in ``tools/architecture.py``; ``docs/architecture.md`` explains them.
"""

from __future__ import annotations

import importlib.util
import sys

from conftest import ROOT

_spec = importlib.util.spec_from_file_location("architecture", ROOT / "tools" / "architecture.py")
assert _spec is not None and _spec.loader is not None
architecture = importlib.util.module_from_spec(_spec)
sys.modules["architecture"] = architecture
_spec.loader.exec_module(architecture)


def test_every_module_sits_in_a_layer_and_imports_only_downward_without_cycles() -> None:
    problems = architecture.violations()
    assert problems == [], "\n".join(problems)


def test_the_tool_finds_a_cycle_and_an_upward_import() -> None:
    """The checks can fail: a made-up graph with a loop has exactly that loop."""
    assert architecture.cycles({("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")}) == [["a", "b", "c"]]
    assert architecture.cycles({("a", "b"), ("b", "c")}) == []
    assert architecture.LAYERS["cli"] > architecture.LAYERS["planner"] > architecture.LAYERS["engine"]


def test_the_diagram_in_the_docs_is_the_one_the_code_draws() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    between = text.split(architecture.BEGIN)[1].split(architecture.END)[0].strip()
    assert between == architecture.mermaid(), "run: python tools/architecture.py --write"


def test_every_package_and_top_level_module_is_described_in_the_docs() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    nodes = {architecture.node_of(architecture._module_name(p)) for p in (ROOT / "fixplan").rglob("*.py")}
    missing = sorted(n for n in nodes - {"fixplan", "__main__"} if f"`{n}" not in text)
    assert missing == [], f"docs/architecture.md does not mention: {missing}"
