"""The README's examples against the code (the README once drifted from the code; these keep them together).

- the ``classify --json`` example's numbers are what the command prints (rounded as shown);
- the Python API block runs (the two ``fixplan.solve`` lines are checked by signature only: a
  plan takes seconds and ``tests/test_solve.py`` runs one);
- ``sim.state`` has ``.pose`` and ``.twist``; the certificate table names every certificate the
  classifier can return, ``zero-wrench`` included;
- the FCLib sample in ``examples/`` solves, and its normal impulses carry the weight;
- every ``fixplan`` command the README shows parses (options and values), the quickstart's
  table row is what ``classify`` prints, the JSON example's ``solve_time_s`` is within
  :data:`SOLVE_TIME_FACTOR` of a real first call, the default fixture's comment gives its computed
  gaps, and which commands take ``mesh`` parts.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import re
import subprocess

import numpy as np
import pytest
from conftest import ROOT, run_cli

import fixplan

README = (ROOT / "README.md").read_text(encoding="utf-8")


def fixplan_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return run_cli(*args, timeout=300, cwd=ROOT)


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def _assert_numbers_match(shown, actual, path: str = "") -> None:
    """Every number the README shows is the code's to the digits shown (``"..."`` stands for anything)."""
    if shown == "...":
        return
    if isinstance(shown, dict):
        for k, v in shown.items():
            assert k in actual, f"README shows {path}.{k}, the code has no such field"
            _assert_numbers_match(v, actual[k], f"{path}.{k}")
    elif isinstance(shown, list):
        assert len(shown) == len(actual), path
        for i, (a, b) in enumerate(zip(shown, actual, strict=True)):
            _assert_numbers_match(a, b, f"{path}[{i}]")
    elif isinstance(shown, bool) or isinstance(shown, str):
        assert shown == actual, path
    elif isinstance(shown, int | float):
        assert actual == pytest.approx(shown, rel=1e-3, abs=1e-9 if shown == 0 else 0.0), path
    else:  # pragma: no cover
        raise AssertionError(f"unexpected {type(shown)} at {path}")


def test_classify_json_example_is_what_the_code_prints() -> None:
    block = next(b for b in _blocks("json") if '"certificate": "sliding-witness"' in b)
    shown = json.loads(block)
    proc = fixplan_cli("classify", "--wrench", "6,0,0,0,0,0", "--json")
    assert proc.returncode == 0, proc.stderr
    actual = json.loads(proc.stdout)
    assert shown["contacts"] == actual["contacts"]
    result, got = shown["results"][0], actual["results"][0]
    for key in ("residuals", "solve_time_s"):  # solver-dependent to the last digits: shape only
        assert set(result[key] if isinstance(result[key], dict) else {}) <= set(
            got[key] if isinstance(got[key], dict) else {}
        )
    result = {k: v for k, v in result.items() if k not in ("residuals", "solve_time_s")}
    _assert_numbers_match(result, got, "results[0]")
    assert got["residuals"]["normal_balance"] == pytest.approx(
        shown["results"][0]["residuals"]["normal_balance"], rel=1e-3
    )
    assert got["residuals"]["balance"] == pytest.approx(shown["results"][0]["residuals"]["balance"], rel=1e-3)


def test_python_api_block_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    block = next(b for b in _blocks("python") if "fixplan.load(" in b)
    lines = block.splitlines()
    solve_lines = [line for line in lines if "fixplan.solve(" in line]
    assert len(solve_lines) == 2
    signature = inspect.signature(fixplan.solve)
    for line in solve_lines:
        call = line.split("#")[0].split("=", 1)[1].strip()
        kwargs = dict(re.findall(r"(\w+)=([^,)]+)", call))
        signature.bind(object(), **kwargs)  # the keywords the README uses exist
    uses_plan = re.compile(r"^\s*plan\b|\bplan\.")
    runnable = "\n".join(line for line in lines if not uses_plan.search(line.split("#")[0]))
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    exec(compile(runnable, "README.md", "exec"), namespace)  # noqa: S102 - the README's own example
    res, sim = namespace["res"], namespace["sim"]
    # pushing the located box away from E1 (+x): no force keeps every contact, and no motion is given
    assert (res[0].mode, res[0].certificate, res[0].acceleration) == ("separates", "no-maintained-motion", None)
    state = sim.state
    assert state.pose is state[0] and np.array_equal(state.twist, state[1]) and state.twist.shape == (6,)
    from fixplan.planner.solve import PlanResult

    names = {f.name for f in dataclasses.fields(PlanResult)} | {n for n in dir(PlanResult) if not n.startswith("_")}
    for field in re.findall(r"\bplan\.(\w+)", block):  # plan.verification, plan.friction_robustness, ...
        assert field in names, f"the README reads plan.{field}; PlanResult has no such field"


def test_certificate_table_is_complete() -> None:
    source = (ROOT / "fixplan" / "jamming" / "classify.py").read_text(encoding="utf-8")
    # result("mode", margin, forces, "certificate", ...): the fourth argument of every result call
    certificates = set(re.findall(r'result\(\s*"\w+",\s*[^,]+,\s*[^,]+,\s*"([\w-]+)"', source))
    assert {"zero-wrench", "normal-balance", "sliding-witness", "opening-witness"} <= certificates, certificates
    table = README[README.index("| mode | meaning | certificate |") :].split("\n\n")[0]
    missing = [c for c in certificates if f"`{c}`" not in table]
    assert not missing, f"certificates missing from the README's table: {missing}"


def test_fclib_sample_solves_and_carries_the_weight() -> None:
    sample = ROOT / "examples" / "box-3-contacts.hdf5"
    assert f"fixplan fclib examples/{sample.name}" in (ROOT / "examples" / "README.md").read_text(encoding="utf-8")
    proc = fixplan_cli("fclib", str(sample), "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["kind"] == "local" and out["contacts"] == 3 and out["converged"]
    r = np.array(out["reaction"]).reshape(3, 3)
    fx = fixplan.load(fixplan.fixture.default_fixture_path())
    assert r[:, 0].sum() == pytest.approx(fx.workpiece.mass_kg * 9.81 * 1e-3, rel=1e-6)  # m g h [N·s]
    assert np.all(r[:, 0] > 0)
    assert np.max(np.abs(out["velocity"])) < 1e-8  # held: no contact velocity


# -- the README's commands and numbers against a real run ------------------------------------------
SOLVE_TIME_FACTOR = 10.0  # the README's first-call solve_time_s, within this factor of a real first call


def test_classify_json_example_solve_time_is_a_first_call_within_a_factor() -> None:
    # the example once showed 0.0004 s: a warm call's time, 1000 times below what a user's first call prints
    block = next(b for b in _blocks("json") if '"certificate": "sliding-witness"' in b)
    shown = json.loads(block)["results"][0]["solve_time_s"]
    proc = fixplan_cli("classify", "--wrench", "6,0,0,0,0,0", "--json")
    got = json.loads(proc.stdout)["results"][0]["solve_time_s"]
    assert shown / SOLVE_TIME_FACTOR <= got <= shown * SOLVE_TIME_FACTOR, (shown, got)
    assert f"a factor of {SOLVE_TIME_FACTOR:g} either way" in README


def _readme_commands() -> list[list[str]]:
    """Every ``fixplan ...`` command the README shows: in code blocks (``$``-prompted or plain) and in
    inline code, without placeholders (``[--opt]``, ``FILE``, ``...``)."""
    import shlex

    lines = [line for lang in ("sh", "text") for b in _blocks(lang) for line in b.splitlines()]
    lines += re.findall(r"`((?:\.venv/bin/)?fixplan [^`]+)`", README.replace("\n", " "))
    commands = []
    for line in lines:
        line = line.split("#")[0].strip().removeprefix("$ ").removesuffix("&").strip()
        line = line.removeprefix(".venv/bin/")
        if not line.startswith("fixplan ") or re.search(r"\[|\.\.\.|…|\b[A-Z]{2,}\b|\bK\b|\bP\b", line):
            continue
        commands.append(shlex.split(line)[1:])
    return commands


def test_every_readme_command_parses() -> None:
    import typer.main

    from fixplan.cli import app

    group = typer.main.get_command(app)
    commands = _readme_commands()
    assert len(commands) >= 15, commands  # the README shows many; a broken extraction finds few
    bad = []
    for args in commands:
        name, rest = args[0], args[1:]
        if name.startswith("-"):  # fixplan --version
            assert name in {"--version", "--help"}, args
            continue
        if rest and rest[-1].startswith("--") and name in group.commands:  # type: ignore[attr-defined]
            # prose names an option without its value ("`fixplan solve --out`"): parse the rest
            flags = {o for p in group.commands[name].params if getattr(p, "is_flag", False) for o in p.opts}  # type: ignore[attr-defined]
            rest = rest if rest[-1] in flags else rest[:-1]
        if name not in group.commands:  # type: ignore[attr-defined]
            bad.append(f"fixplan {' '.join(args)}: no command {name!r}")
            continue
        if not rest:  # prose names the command ("`fixplan verify` replays ..."): it exists
            continue
        try:
            group.commands[name].make_context(name, list(rest), resilient_parsing=False)  # type: ignore[attr-defined]
        except Exception as exc:  # noqa: BLE001 - a click usage error names what is wrong
            bad.append(f"fixplan {' '.join(args)}: {exc}")
    assert not bad, "\n".join(bad)


def test_the_quickstart_classify_block_is_what_the_command_prints() -> None:
    block = next(b for b in _blocks("text") if "$ .venv/bin/fixplan classify --wrench 6,0,0,0,0,0" in b)
    proc = fixplan_cli("classify", "--wrench", "6,0,0,0,0,0")
    assert proc.returncode == 0, proc.stderr
    row = next(line for line in block.splitlines() if line.startswith("│ 1 "))
    assert [c.strip() for c in row.split("│")[1:-1]] in [
        [c.strip() for c in line.split("│")[1:-1]] for line in proc.stdout.splitlines() if line.startswith("│ 1 ")
    ], proc.stdout


def test_the_default_fixture_comment_gives_its_computed_gaps() -> None:
    from fixplan.fixture import default_fixture_path
    from fixplan.locating import locator_gaps

    path = default_fixture_path()
    comment = "".join(line for line in path.read_text(encoding="utf-8").splitlines() if line.startswith("#"))
    quoted = {name: float(mm) for mm, name in re.findall(r"([\d.]+) mm to (\w+)", comment.replace("#", ""))}
    fx = fixplan.load(path)
    gaps = dict(zip([loc.name for loc in fx.locators], locator_gaps(fx.workpiece, fx.start, fx.locators), strict=True))
    open_ = {n for n, g in gaps.items() if g > fx.tolerances.touch_m}
    assert set(quoted) == open_ == {"S1", "S2", "E1"}
    for name, mm in quoted.items():
        assert gaps[name] * 1e3 == pytest.approx(mm, abs=0.05), name  # to the digit shown


def test_the_fixture_section_says_which_commands_take_mesh_parts(tmp_path) -> None:
    section = README[README.index("## Fixture files") :].split("\n## ")[0]
    assert "every command takes it" in section
    # ... and that is what the commands do
    from fixplan.cli import main
    from fixplan.geometry.cells import box_cells, cell_surface
    from fixplan.geometry.mesh import stl_bytes

    V, F = cell_surface(*box_cells((0.2, 0.1, 0.05), 1))
    (tmp_path / "p.stl").write_bytes(stl_bytes(V, F))
    text = (ROOT / "problems" / "box-3-2-1.toml").read_text()
    text = text.replace('shape = "box"\nsize = [0.20, 0.10, 0.05]', 'shape = "mesh"\nfile = "p.stl"')
    (tmp_path / "m.toml").write_text("\n".join(ln for ln in text.splitlines() if not ln.startswith("face = ")))
    assert fixplan.load(tmp_path / "m.toml").workpiece.shape.name == "mesh"
    assert main(["solve", str(tmp_path / "m.toml")]) == 0  # located at its start: nothing to plan
