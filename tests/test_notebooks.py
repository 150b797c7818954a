"""The notebooks are committed with their outputs, as ``make gallery`` stores them.

GitHub and a reader who opens a notebook without running it see what it printed and drew, so
the stored outputs must be those of the notebook's current code, run top to bottom in one kernel
in full mode, without an error, with every figure stored as a PNG of moderate size.
(``make test`` also runs each notebook afresh with ``pytest --nbmake``, which does not write
back; these tests read the files only.)
"""

from __future__ import annotations

import base64
import importlib.util
import json

import pytest
from conftest import ROOT

_spec = importlib.util.spec_from_file_location("notebooks_tool", ROOT / "tools" / "notebooks.py")
assert _spec is not None and _spec.loader is not None
notebooks_tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(notebooks_tool)

NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
MAX_NOTEBOOK_BYTES = 600_000
MAX_FIGURE_PX = 1100  # the widest figure, 12 in at the gallery's 80 dpi, is about 960 px
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _load(path):
    return json.loads(path.read_text(encoding="utf-8"))


def _code_cells(nb):
    return [c for c in nb["cells"] if c["cell_type"] == "code"]


def _source(cell) -> str:
    return cell["source"] if isinstance(cell["source"], str) else "".join(cell["source"])


def _png_size(data: bytes) -> tuple[int, int]:
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_the_seven_notebooks_are_there():
    assert [p.name[:3] for p in NOTEBOOKS] == ["01-", "02-", "03-", "04-", "05-", "06-", "07-"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_stored_outputs_are_those_of_the_current_code(path):
    nb = _load(path)
    stored = nb["metadata"].get("fixplan", {}).get("code_sha256")
    assert stored == notebooks_tool.code_sha256(nb), f"{path.name}: outputs stale or missing; run make gallery"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_code_cell_ran_once_in_order_without_error(path):
    cells = _code_cells(_load(path))
    # one kernel, top to bottom: the execution counts are 1, 2, ..., n
    assert [c["execution_count"] for c in cells] == list(range(1, len(cells) + 1)), path.name
    for k, cell in enumerate(cells, 1):
        kinds = [o["output_type"] for o in cell["outputs"]]
        assert "error" not in kinds, f"{path.name} cell {k}"
        assert not [o for o in cell["outputs"] if o.get("name") == "stderr"], f"{path.name} cell {k} wrote to stderr"
    # full mode, not FIXPLAN_SHORT's shortened runs: the last cell reports it
    last = "".join("".join(o.get("text", "")) for o in cells[-1]["outputs"])
    assert "(SHORT = False)" in last, f"{path.name}: {last!r}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_plot_is_stored_as_a_moderate_png(path):
    assert path.stat().st_size <= MAX_NOTEBOOK_BYTES, f"{path.name}: {path.stat().st_size} bytes"
    n_images = 0
    for k, cell in enumerate(_code_cells(_load(path)), 1):
        images = [o["data"]["image/png"] for o in cell["outputs"] if "image/png" in o.get("data", {})]
        draws = "plt.show()" in _source(cell)
        # a figure shown as text only ("<Figure size ...>") means a non-drawing backend ran it
        assert not draws or images, f"{path.name} cell {k} draws a figure but stores no image"
        for b64 in images:
            width, height = _png_size(base64.b64decode(b64))
            assert 100 <= width <= MAX_FIGURE_PX and 100 <= height <= MAX_FIGURE_PX, (path.name, k, width, height)
        n_images += len(images)
        for o in cell["outputs"]:
            assert "text/html" not in o.get("data", {}), f"{path.name} cell {k}: HTML output"
    assert n_images >= 1, path.name


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_no_volatile_metadata(path):
    # what changes between runs of unchanged code is not stored, so a re-run's diff stays small
    nb = _load(path)
    for cell in nb["cells"]:
        assert "execution" not in cell["metadata"] and "ExecuteTime" not in cell["metadata"], path.name
    assert set(nb["metadata"].get("language_info", {})) <= {"name"}, path.name
    assert nb["metadata"]["kernelspec"]["name"] == "python3"
