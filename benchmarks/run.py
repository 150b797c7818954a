"""Run every benchmark and write benchmarks/REPORT.md plus one CSV per benchmark.

Each ``benchmarks/bench_*.py`` module defines ``run(quick: bool) -> Section``: the rows it
measured (one per case, method and setting, with time *and* error) and the Markdown it wants
in the report. This file only collects them, adds the machine and versions, and writes.

Each section sits between ``<!-- bench:NAME -->`` and ``<!-- /bench:NAME -->`` markers. With
``--only`` the report is not rewritten: only the named sections are replaced (or appended when
the report has no markers for them yet), so the other benchmarks' figures are kept.
"""

from __future__ import annotations

import argparse
import csv
import importlib
import platform
import sys
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


@dataclass
class Section:
    """What one benchmark module reports."""

    title: str
    markdown: str
    rows: list[dict] = field(default_factory=list)
    csv_name: str = ""  # results/<csv_name>.csv; default: the module's name


def machine_markdown() -> str:
    import os

    lines = [
        f"- date: {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}",
        f"- machine: {platform.machine()}, {os.cpu_count()} cores, {platform.platform()}",
        f"- python: {platform.python_version()}",
    ]
    try:
        with open("/proc/cpuinfo") as fh:
            model = next((ln.split(":", 1)[1].strip() for ln in fh if "model name" in ln), "?")
        lines.append(f"- cpu: {model}")
    except OSError:
        pass
    versions = []
    for name in ("fixplan", "numpy", "scipy", "cvxpy", "clarabel", "numba", "casadi", "pinocchio", "mujoco"):
        try:
            mod = importlib.import_module(name)
            versions.append(f"{name} {getattr(mod, '__version__', '?')}")
        except Exception:  # noqa: BLE001 - a missing optional package is reported, not fatal
            versions.append(f"{name} (not installed)")
    lines.append("- versions: " + ", ".join(versions))
    return "\n".join(lines)


def splice(report: str, name: str, block: str) -> str:
    """``report`` with the section between ``name``'s markers replaced by ``block`` (appended if absent)."""
    begin, end = f"<!-- bench:{name} -->", f"<!-- /bench:{name} -->"
    i, j = report.find(begin), report.find(end)
    if i < 0 or j < i:
        return report.rstrip("\n") + "\n\n" + block
    tail = report[j + len(end) :].lstrip("\n")
    return report[:i] + block + ("\n" + tail if tail else "")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    parser.add_argument("--only", default="", help="comma-separated benchmark names")
    parser.add_argument("--out", default=str(HERE / "REPORT.md"))
    args = parser.parse_args()
    names = sorted(p.stem for p in HERE.glob("bench_*.py"))
    if args.only:
        wanted = {f"bench_{n.removeprefix('bench_')}" for n in args.only.split(",")}
        names = [n for n in names if n in wanted]
    results_dir = HERE / "results"
    results_dir.mkdir(exist_ok=True)
    # bytecode for every module, as an installed package has after its first run: an edited
    # checkout under PYTHONDONTWRITEBYTECODE recompiled its stale modules in every timed process
    # (0.1 s of a 1 s 2D solve)
    import compileall

    compileall.compile_dir(str(HERE.parent / "fixplan"), quiet=1)
    parts = ["# fixplan benchmark report", "", machine_markdown(), ""]
    blocks: dict[str, str] = {}
    for name in names:
        t0 = time.perf_counter()
        print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        section: Section = importlib.import_module(name).run(quick=args.quick)
        elapsed = time.perf_counter() - t0
        block = [f"<!-- bench:{name} -->", f"## {section.title}", "", section.markdown.strip(), ""]
        block += [f"_({name}: {elapsed:.1f} s)_", f"<!-- /bench:{name} -->", ""]
        blocks[name] = "\n".join(block)
        parts += block
        if section.rows:
            with open(results_dir / f"{section.csv_name or name}.csv", "w", newline="") as fh:
                fields: list[str] = []
                for row in section.rows:  # rows of one benchmark may differ (e.g. two tables)
                    fields += [k for k in row if k not in fields]
                writer = csv.DictWriter(fh, fieldnames=fields)
                writer.writeheader()
                writer.writerows(section.rows)
    out = Path(args.out)
    if args.only and out.is_file():
        text = out.read_text()
        for name, block in blocks.items():
            text = splice(text, name, block)
        out.write_text(text)
    else:
        out.write_text("\n".join(parts))
    print(f"[bench] wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
