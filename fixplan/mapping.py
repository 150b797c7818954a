"""Jamming maps: two wrench components on a grid, classified (drawn by :func:`fixplan.present.maps.save_map`)."""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from fixplan.jamming.classify import MODES
from fixplan.locating import contact_set

if TYPE_CHECKING:
    from fixplan.model import Fixture


@dataclass(frozen=True)
class JammingMap:
    """Modes and balance residuals on a grid of two wrench components.

    ``margins`` holds each cell's :attr:`~fixplan.jamming.classify.Classification.balance_residual`
    [N/√kg] (the CSV column keeps the name ``margin``).
    """

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
    margins = np.array([r.balance_residual for r in results]).reshape(n, n)
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
