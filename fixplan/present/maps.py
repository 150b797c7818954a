"""The jamming diagram: a :class:`~fixplan.mapping.JammingMap` drawn like Whitney's diagram, and its grid as CSV.

matplotlib is imported inside :func:`save_map`; the figure is a plain ``Figure`` (no pyplot, no
backend switch), so it draws headless and leaves a notebook's backend alone.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fixplan.files import write_output
from fixplan.jamming.classify import MODES
from fixplan.mapping import axis_unit

if TYPE_CHECKING:
    from fixplan.mapping import JammingMap

MODE_COLORS = {
    "held": "#4c72b0",
    "jammed": "#c44e52",
    "separates": "#dddddd",
    "slides": "#55a868",
    "pivots": "#dd8452",
    "rolls": "#8172b2",
    "indeterminate": "#000000",
}


def save_map(result: JammingMap, png: Path, csv_path: Path | None = None) -> None:
    """Write the diagram as a PNG (matplotlib, no display needed) and the grid as CSV."""
    # a Figure of its own (no pyplot, no backend switch): safe headless and inside a notebook
    from matplotlib.colors import ListedColormap
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    codes = {m: k for k, m in enumerate(MODES)}
    grid = np.vectorize(codes.get)(result.modes)
    cmap = ListedColormap([MODE_COLORS[m] for m in MODES])
    fig = Figure(figsize=(6, 5), dpi=100)
    ax = fig.subplots()
    ax.imshow(
        grid,
        origin="lower",
        extent=(result.x[0], result.x[-1], result.y[0], result.y[-1]),
        aspect="auto",
        cmap=cmap,
        vmin=-0.5,
        vmax=len(MODES) - 0.5,
        interpolation="nearest",
    )
    ax.set_xlabel(f"{result.axis_names[0]} [{axis_unit(result.axis_names[0])}]")
    ax.set_ylabel(f"{result.axis_names[1]} [{axis_unit(result.axis_names[1])}]")
    ax.set_title(result.title, fontsize=9)
    present = [m for m in MODES if (result.modes == m).any()]
    ax.legend(
        handles=[Patch(color=MODE_COLORS[m], label=m) for m in present], loc="upper right", fontsize=8, framealpha=0.9
    )
    fig.tight_layout()
    write_output(png, fig.savefig)
    if csv_path is not None:
        save_map_csv(result, csv_path)


def save_map_csv(result: JammingMap, csv_path: Path) -> None:
    """Write the grid as CSV: one row per point (the two axes, the mode, the margin); see :func:`fixplan.files.write_output`."""

    def write(path: Path) -> None:
        with open(path, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow([result.axis_names[0], result.axis_names[1], "mode", "margin"])
            for j, yv in enumerate(result.y):
                for i, xv in enumerate(result.x):
                    writer.writerow([f"{xv:.9g}", f"{yv:.9g}", result.modes[j, i], f"{result.margins[j, i]:.6g}"])

    write_output(csv_path, write)
