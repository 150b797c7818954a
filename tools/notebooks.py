"""Run the notebooks in place and store their outputs: ``python tools/notebooks.py [NOTEBOOK ...]``.

``make gallery`` runs it on every notebook in ``notebooks/`` so that GitHub, and a reader who
opens a notebook without running it, sees the printed results and the plots. Each notebook runs
top to bottom in a fresh kernel (nbclient), in full mode (``FIXPLAN_SHORT`` unset), with the
matplotlib inline backend (``MPLBACKEND`` unset) drawing PNG figures at a moderate resolution.

Re-running gives small diffs: the notebooks draw no random numbers (``PYTHONHASHSEED`` is fixed
as well), nbclient records no execution timestamps, and what changes from run to run without the
code changing is dropped (the kernel's Python version, cell execution metadata). Only what is
measured on the machine changes: wall times and the plots of them (notebooks 03 and 05).

The notebook's metadata keeps the digest of its code cells (``fixplan.code_sha256``):
``tests/test_notebooks.py`` compares it with the code, so a notebook whose code was edited
without re-running it fails the tests instead of showing outputs of other code.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = ROOT / "notebooks"
FIGURE_DPI = 80
"""The inline figures' resolution [dpi]: at 80 the largest figure (12 × 6.5 in) is about 960 × 520 px."""
CELL_TIMEOUT_S = 3600
KERNEL_ENV = {"PYTHONHASHSEED": "0"}
KERNEL_ENV_UNSET = ("FIXPLAN_SHORT", "MPLBACKEND")


def code_sha256(nb: dict) -> str:
    """Digest of the notebook's code cells, in order (the outputs depend on nothing else in the file)."""
    h = hashlib.sha256()
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            src = cell["source"] if isinstance(cell["source"], str) else "".join(cell["source"])
            h.update(src.encode("utf-8") + b"\0")
    return h.hexdigest()


def strip_volatile(nb: dict) -> None:
    """Drop what changes between runs of unchanged code: execution metadata, the kernel's versions."""
    for cell in nb["cells"]:
        cell["metadata"].pop("execution", None)
        cell["metadata"].pop("ExecuteTime", None)
    info = nb["metadata"].get("language_info")
    if info is not None:
        nb["metadata"]["language_info"] = {"name": info.get("name", "python")}
    nb["metadata"].pop("widgets", None)


def execute(path: Path) -> float:
    """Run one notebook in place (outputs stored); returns the wall time [s]."""
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
        record_timing=False,
        extra_arguments=[f"--InlineBackend.rc=figure.dpi={FIGURE_DPI}"],
    )
    t0 = time.perf_counter()
    client.execute()
    wall_s = time.perf_counter() - t0
    strip_volatile(nb)
    nb.metadata["fixplan"] = {"code_sha256": code_sha256(nb), "executed_by": "make gallery (tools/notebooks.py)"}
    nbformat.validate(nb)
    nbformat.write(nb, path)
    return wall_s


def main(argv: list[str] | None = None) -> int:
    """Run the notebooks named on the command line (default: all); exit status 2 if one is missing."""
    parser = argparse.ArgumentParser(prog="python tools/notebooks.py", description=__doc__.splitlines()[0])
    parser.add_argument("notebooks", nargs="*", type=Path, help="notebooks to run (default: all in notebooks/)")
    args = parser.parse_args(argv)
    paths = args.notebooks or sorted(NOTEBOOKS.glob("*.ipynb"))
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        print(f"tools/notebooks.py: expected notebook files, not found: {', '.join(missing)}", file=sys.stderr)
        return 2
    # the kernel inherits this process's environment
    for name in KERNEL_ENV_UNSET:
        os.environ.pop(name, None)
    os.environ.update(KERNEL_ENV)
    for path in paths:
        wall_s = execute(path)
        print(f"{path.name}: ran in {wall_s:.0f} s, {path.stat().st_size / 1e3:.0f} kB with outputs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
