"""``fixplan solve --batch DIR``: plan (and verify) every fixture file of a directory as Dask tasks.

Each task receives a file's path and TOML text (so a worker on another machine needs neither the
file nor a shared disk), loads it with :func:`fixplan.fixture.loads` and returns a small summary.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from fixplan.errors import FixplanError, FixtureError, InputError


def fixture_files(directory: Path) -> list[Path]:
    """The ``*.toml`` fixture files of ``directory`` (sorted), without expected-verdict tables."""
    from fixplan.expectations import looks_like_expectations, read_toml

    if not directory.is_dir():
        raise InputError(
            f"fixture_files.directory {directory}: not a directory (expected a directory of fixture files)"
        )
    files = []
    for path in sorted(directory.glob("*.toml")):
        data = read_toml(path)
        if data is not None and looks_like_expectations(data):
            continue
        files.append(path)
    if not files:
        raise InputError(f"fixture_files.directory {directory}: no *.toml fixture files")
    return files


def solve_text(item: tuple[str, str], options: dict[str, Any]) -> dict[str, Any]:
    """One Dask task: load the fixture ``(path, text)``, plan and verify it; a JSON-ready summary."""
    from fixplan.fixture import loads
    from fixplan.planner.solve import solve

    source, text = item
    t0 = time.perf_counter()
    out: dict[str, Any] = {"file": source, "name": None, "sequence": [], "verification": None}
    try:
        fixture = loads(text, source=source, base_dir=Path(source).parent)
        out["name"] = fixture.name
        result = solve(fixture, **options)
    except FixtureError as exc:
        return {**out, "status": "invalid", "reason": "; ".join(i.format(source) for i in exc.issues),
                "time_s": time.perf_counter() - t0}  # fmt: skip
    except FixplanError as exc:
        return {**out, "status": "error", "reason": str(exc), "time_s": time.perf_counter() - t0}
    v = result.verification
    return {
        **out,
        "status": result.status,
        "reason": result.reason,
        "sequence": [list(s) for s in result.sequence],
        "verification": None if v is None else {"passed": bool(v.passed), "reason": v.reason},
        "time_s": time.perf_counter() - t0,
    }


def solve_batch(
    files: Sequence[Path],
    options: dict[str, Any],
    *,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """Solve every file (``options`` as :func:`fixplan.planner.solve.solve` takes them), in file order."""
    from fixplan.cluster import dask_client, run_tasks
    from fixplan.files import read_user_text

    items = []
    for path in files:
        items.append((str(path), read_user_text(path, expected="a .toml fixture file")))
    with dask_client(scheduler, tasks=len(items)) as client:
        return run_tasks(client, solve_text, items, options, progress=progress, name="fixplan-solve")
