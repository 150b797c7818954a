"""Jamming maps: two wrench components on a grid, classified, drawn like Whitney's diagram."""

from __future__ import annotations

import csv
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.classify import MODES
from fixplan.locating import contact_set

if TYPE_CHECKING:
    from fixplan.fixture import Fixture

MODE_COLORS = {
    "held": "#4c72b0",
    "jammed": "#c44e52",
    "separates": "#dddddd",
    "slides": "#55a868",
    "pivots": "#dd8452",
    "rolls": "#8172b2",
    "indeterminate": "#000000",
}


@dataclass(frozen=True)
class JammingMap:
    """Modes and margins on a grid of two wrench components."""

    axis_names: tuple[str, str]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    modes: NDArray[np.str_]  # (len(y), len(x))
    margins: NDArray[np.float64]
    title: str
    time_s: float
    base: tuple[float, ...] = ()  # the other wrench components (about the body origin), as given

    def counts(self) -> dict[str, int]:
        return {m: int((self.modes == m).sum()) for m in MODES if (self.modes == m).any()}


def jamming_map(
    fixture: Fixture,
    components: tuple[int, int],
    bounds: Sequence[tuple[float, float]],
    n: int,
    *,
    base: NDArray[np.float64] | None = None,
    contacts: Sequence[str] | None = None,
    at: NDArray[np.float64] | None = None,
    pose: str | None = None,
    progress: bool = False,
    axis_names: tuple[str, str] = ("x", "y"),
    jobs: int | None = None,
) -> JammingMap:
    """Classify ``n × n`` wrenches varying two components over ``bounds``."""
    from fixplan.jamming import classify

    cs = contact_set(fixture, pose, contacts)
    base = np.zeros(fixture.ndof) if base is None else np.asarray(base, dtype=float)
    xs = np.linspace(bounds[0][0], bounds[0][1], n)
    ys = np.linspace(bounds[1][0], bounds[1][1], n)
    W = np.tile(base, (n * n, 1))
    X, Y = np.meshgrid(xs, ys)  # row j: y = ys[j]
    W[:, components[0]] = X.ravel()
    W[:, components[1]] = Y.ravel()
    t0 = time.perf_counter()
    bar = None
    callback = None
    if progress:
        from rich.console import Console
        from rich.progress import Progress

        bar = Progress(transient=True, console=Console(file=sys.stderr))
        bar.start()
        task = bar.add_task("classifying", total=n * n)

        def callback(k: int) -> None:
            bar.update(task, advance=k)

    try:
        results = classify(fixture, W, contacts, at, pose=pose, progress=callback, jobs=jobs)
    finally:
        if bar is not None:
            bar.stop()
    modes = np.array([r.mode for r in results], dtype=object).reshape(n, n)
    margins = np.array([r.margin for r in results]).reshape(n, n)
    elapsed = time.perf_counter() - t0
    title = f"{fixture.name}: contacts {', '.join(cs.names)}"
    others = [k for k in range(fixture.ndof) if k not in components]
    if np.any(base[others] != 0.0):
        names = WRENCH_AXES[fixture.dimension]
        title += "\nother components: " + ", ".join(f"{names[k]} = {base[k]:g} {axis_unit(names[k])}" for k in others)
    return JammingMap(axis_names, xs, ys, modes.astype(str), margins, title, elapsed, tuple(float(x) for x in base))


WRENCH_AXES = {3: ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz"), 2: ("Fx", "Fy", "Mz")}


def axis_unit(name: str) -> str:
    """``N`` for a force component (``Fx``), ``N·m`` for a moment (``Tz``, ``Mz``)."""
    return "N" if name.startswith("F") else "N·m"


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
    fig.savefig(png)
    if csv_path is not None:
        with open(csv_path, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow([result.axis_names[0], result.axis_names[1], "mode", "margin"])
            for j, yv in enumerate(result.y):
                for i, xv in enumerate(result.x):
                    writer.writerow([f"{xv:.9g}", f"{yv:.9g}", result.modes[j, i], f"{result.margins[j, i]:.6g}"])
