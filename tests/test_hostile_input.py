"""Hostile input, case by case: each bad file, option or command line gets exit 2, its exact message, and loses nothing.

The fuzz suite (``tests/fuzz``) keeps the contract on random input; these tests pin the
messages and numbers of the cases once reported. The CLI runs in-process (``main(argv)``)
except where a run could block (a named pipe), which runs in a subprocess with a timeout.
"""

from __future__ import annotations

import codecs
import errno
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CLI, PROBLEMS, ROOT

from fixplan import limits
from fixplan.cli import main
from fixplan.errors import InputError
from fixplan.files import write_output

BOX = (PROBLEMS / "box-3-2-1.toml").read_text(encoding="utf-8")


def run(capsys, *args: str) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return code, out, err


def strict_json(text: str) -> dict:
    def refuse(name: str) -> float:
        raise ValueError(name)

    return json.loads(text, parse_constant=refuse)


# -- files and text -------------------------------------------------------------------------
ENCODINGS = {
    "binary": (bytes(range(256)) * 4, "is a binary file (expected a .toml fixture file)"),
    "invalid-utf8": (
        BOX.encode().replace(b"box-3-2-1", b"box-\xff-2-1", 1),
        "is not UTF-8 text: byte 0xff on line 1 (expected a .toml fixture file in UTF-8)",
    ),
    "utf16": (BOX.encode("utf-16"), "is UTF-16 text (expected a .toml fixture file in UTF-8: save it as UTF-8)"),
    "hdf5": (
        (ROOT / "examples" / "box-3-contacts.hdf5").read_bytes(),
        "is an HDF5 file (expected a .toml fixture file; FCLib problems are read by 'fixplan fclib')",
    ),
}


@pytest.mark.parametrize("kind", sorted(ENCODINGS))
@pytest.mark.parametrize("command", ["validate", "classify", "solve"])
def test_unreadable_fixture_is_one_line_exit_2(capsys, tmp_path: Path, kind: str, command: str) -> None:
    data, reason = ENCODINGS[kind]
    path = tmp_path / "f.toml"
    path.write_bytes(data)
    extra = {"validate": [], "classify": ["--wrench", "0,0,0,0,0,0"], "solve": ["--no-verify"]}[command]
    code, out, err = run(capsys, command, path, *extra)
    assert code == 2
    assert err == f"{path}: <file>: cannot read: {reason}\n"
    assert path.read_bytes() == data


def test_utf8_bom_is_accepted(capsys, tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    path.write_bytes(codecs.BOM_UTF8 + BOX.encode())
    code, out, _ = run(capsys, "validate", path)
    assert code == 0 and out.startswith(f"{path}: ok (")


def test_binary_and_bad_wrench_csv(capsys, tmp_path: Path) -> None:
    binary = tmp_path / "w.csv"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR")
    code, _, err = run(capsys, "classify", "--wrenches", binary)
    assert code == 2 and err.startswith(f"fixplan: {binary}: cannot read: is a binary file")
    bad = tmp_path / "bad.csv"
    bad.write_text("Fx,Fy,Fz,Tx,Ty,Tz\n1,2\n0,0,0,0,0,0\nx,1,1,1,1,1\n1e308,0,0,0,0,0\n")
    code, _, err = run(capsys, "classify", "--wrenches", bad)
    assert code == 2
    assert err.splitlines() == [  # every bad line, not only the first
        f"{bad}: line 2: wrench expects 6 numbers, got 2 in '1,2'",
        f"{bad}: line 4: wrench must be comma-separated numbers, got 'x,1,1,1,1,1'",
        # the number as written in the file: never reformatted or rounded
        f"{bad}: line 5: wrench: number 1 is 1e308 (expected a force component [N] in [-1e+06, 1e+06])",
    ]


@pytest.mark.parametrize("depth", [1000, 5000])
def test_deeply_nested_toml(capsys, tmp_path: Path, depth: int) -> None:
    path = tmp_path / "deep.toml"
    path.write_text(BOX + "\nextra = " + "[" * depth + "1" + "]" * depth + "\n")
    code, _, err = run(capsys, "validate", path)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith(f"{path}: ")
    assert "nested" in err and "deep (expected at most" in err  # refused before parsing


def test_named_pipe_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "f.toml"
    os.mkfifo(fifo)
    t0 = time.perf_counter()
    proc = subprocess.run(
        [*CLI, "validate", str(fifo)],
        capture_output=True,
        text=True,
        timeout=30,
        stdin=subprocess.DEVNULL,
    )
    assert proc.returncode == 2 and time.perf_counter() - t0 < 30
    assert proc.stderr == (
        f"{fifo}: <file>: cannot read: is not a regular file but a named pipe (expected a .toml fixture file)\n"
    )


def _many_locators(n: int) -> str:
    head = BOX.split("[[locator]]")[0]
    rows = [
        f'[[locator]]\nname = "L{i}"\nposition = [{0.001 * (i % 200):.3f}, {0.001 * (i // 200):.3f}, -0.01]\nfriction = 0.2\n'
        for i in range(n)
    ]
    return head + "\n".join(rows)


def test_many_locators_refused_fast(capsys, tmp_path: Path) -> None:
    big = tmp_path / "big.toml"
    big.write_text(_many_locators(20000))  # about 1.5 MB, as once reported
    t0 = time.perf_counter()
    code, _, err = run(capsys, "validate", big)
    assert code == 2 and time.perf_counter() - t0 < 5
    assert f"larger than the limit of {limits.MAX_FILE_BYTES} bytes" in err
    many = tmp_path / "many.toml"
    many.write_text(_many_locators(5000))  # under 1 MiB: refused by the count, before any check
    t0 = time.perf_counter()
    code, _, err = run(capsys, "validate", many)
    assert code == 2 and time.perf_counter() - t0 < 5
    assert err == (
        f"{many}: locator: 5000 [[locator]] and [[contact]] entries (expected at most 100; "
        "a fixture needs 6 in 3D, 3 in 2D)\n"
    )


@pytest.mark.parametrize("name", ["B1\nB2", "\x1b[31mB1\x1b[0m", "B 1", "B1;", "a.b", "x" * 65])
def test_locator_names_are_restricted(capsys, tmp_path: Path, name: str) -> None:
    path = tmp_path / "f.toml"
    path.write_text(BOX.replace('name = "B1"', f"name = {json.dumps(name)}"))
    code, _, err = run(capsys, "validate", path)
    assert code == 2
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].isprintable(), err
    assert lines[0].startswith(f"{path}: locator[0].name: got ")
    assert "expected a name of 1 to 64 letters, digits, '_', '-' or '+'" in lines[0]


def test_no_contacts_to_analyse_names_file_and_nearest(capsys, tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    # lifted 0.1 m: the base locators are 0.1 m below, S1 and S2 0.075 m from the side face's lower edge
    path.write_text(BOX.replace("position = [0.10, 0.05, 0.025]", "position = [0.10, 0.05, 0.125]"))
    code, _, err = run(capsys, "classify", path, "--wrench", "0,0,0,0,0,0")
    assert code == 2
    assert err == (
        f"fixplan: {path}: no contacts to analyse at the start pose: no locator touches the workpiece; "
        "the nearest is S1, 0.075 m away (name hypothetical contacts with --contacts)\n"
    )


def test_point_locators_at_one_place(capsys, tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    path.write_text(BOX.replace("position = [0.16, 0.02, 0.0]", "position = [0.04, 0.02, 0.0]"))
    code, _, err = run(capsys, "validate", path)
    assert code == 2
    assert (
        f"{path}: locator.B2.position: B2 and B1 are at one place (0 m apart; expected point locators at least 1e-06 m apart)"
        in err.splitlines()
    )


# -- commands -------------------------------------------------------------------------------
def test_simulate_duration_zero_and_dt_past_duration(capsys) -> None:
    code, out, _ = run(capsys, "simulate", "--duration", "0", "--json")
    result = strict_json(out)
    assert code == 0 and result["steps"] == 0 and result["time"] == 0.0
    assert result["pose"]["position"] == pytest.approx([0.1, 0.05, 0.025], abs=0.1)
    code, _, err = run(capsys, "simulate", "--duration", "0.1", "--dt", "0.5")
    assert code == 2
    assert err == "fixplan: --dt 0.5 s is longer than --duration 0.1 s (expected a time step ≤ the duration)\n"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--duration", "1e12"], "--duration is 1e+12 (expected a duration [s] in [0, 1e+06])"),
        (["--dt", "1e-300"], "--dt is 1e-300 (expected a time step [s] in [1e-06, 1])"),
        (
            ["--duration", "1e5", "--dt", "1e-6"],
            "--duration 100000 s at a time step of 1e-06 s is 1e+11 steps, more than the limit of 1e+07 "
            "(use --force to run it anyway)",
        ),
    ],
)
def test_simulate_refuses_endless_runs(capsys, args: list[str], message: str) -> None:
    code, _, err = run(capsys, "simulate", *args)
    assert code == 2 and err == f"fixplan: {message}\n"


def test_timestep_in_file_is_range_checked(capsys, tmp_path: Path) -> None:
    path = tmp_path / "f.toml"
    path.write_text(BOX + "\n[simulation]\ntimestep = 1e-300\n")
    code, _, err = run(capsys, "simulate", path)
    assert code == 2
    assert err == f"{path}: simulation.timestep: got 1e-300 (expected a time step [s] in [1e-06, 1])\n"


def test_outputs_to_devices_and_dangling_links(capsys, tmp_path: Path) -> None:
    code, _, err = run(capsys, "simulate", "--duration", "0.01", "--out", "/dev/full", "--force")
    assert code == 2
    assert err == "fixplan: --out /dev/full is a character device, not a regular file (expected a file path)\n"
    link = tmp_path / "traj.csv"
    link.symlink_to(tmp_path / "elsewhere" / "traj.csv")
    code, _, err = run(capsys, "simulate", "--duration", "0.01", "--out", link)
    assert code == 2 and "is a dangling symbolic link" in err
    assert not (tmp_path / "elsewhere").exists()


def test_write_errors_name_the_path() -> None:
    def full(path: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(InputError, match=r"^cannot write out/x\.csv: no space left on the device$"):
        write_output(Path("out/x.csv"), full)


def test_map_out_must_be_an_image(capsys, tmp_path: Path) -> None:
    code, _, err = run(capsys, "map", "--out", tmp_path / "m.csv")
    assert code == 2
    assert "expected an image file ending in .png, .svg or .pdf" in err
    assert not list(tmp_path.iterdir())


def test_solve_refuses_colliding_outputs(capsys, tmp_path: Path) -> None:
    plan = tmp_path / "plan.json"
    plan.write_text('{"a user": "plan"}')
    before = plan.read_bytes()
    code, _, err = run(capsys, "solve", "--out", plan, "--report", plan, "--force", "--no-verify")
    assert code == 2 and "is the same file as --out" in err
    png = tmp_path / "plan.png"
    png.write_bytes(b"a user's figure")
    code, _, err = run(capsys, "solve", "--out", png, "--report", tmp_path / "plan.md", "--force", "--no-verify")
    assert code == 2 and err == (
        f"fixplan: the report's figure {png} is the same file as --out {png} "
        "(an output must not replace an input or another output)\n"
    )
    assert plan.read_bytes() == before and png.read_bytes() == b"a user's figure"
    assert not (tmp_path / "plan.md").exists()


def test_solve_order_is_checked_on_a_located_part(capsys) -> None:
    code, _, err = run(capsys, "solve", PROBLEMS / "box-3-2-1.toml", "--order", "NOPE", "--no-verify")
    assert code == 2 and "--order names unknown locators: NOPE" in err


# -- what a newcomer trips on ---------------------------------------------------------------
def test_bare_fixplan_and_version(capsys) -> None:
    code, out, err = run(capsys)
    assert code == 0 and err == ""
    assert out.startswith("Usage: fixplan [OPTIONS] COMMAND [ARGS]...") and len(out.splitlines()) > 10
    code, out, _ = run(capsys, "--version")
    assert code == 0 and out.startswith("fixplan ")


def test_validate_verbose_shows_goal_and_rank(capsys) -> None:
    bad = PROBLEMS / "box-bad-design.toml"
    code, out, err = run(capsys, "validate", "--verbose", bad)
    assert code == 0
    assert "  rank of G at the goal: 5 of 6: the locators do NOT determine the pose" in out.splitlines()
    assert any(line.startswith("  goal (computed): position [0.1, 0.05, 0.025] m") for line in out.splitlines())
    assert err.splitlines() == [
        f"{bad}: locator: warning: the locators do not determine the pose (rank G = 5 < 6): "
        "the part can move while touching every locator"
    ]


def test_millimetre_file(capsys, tmp_path: Path) -> None:
    mm = tmp_path / "mm.toml"
    mm.write_text(BOX.replace("size = [0.20, 0.10, 0.05]", "size = [200.0, 100.0, 50.0]"))
    code, _, err = run(capsys, "validate", mm)
    assert code == 2 and err == (
        f"{mm}: workpiece.size[0]: got 200 (expected a length [m] in [0.0001, 100]; "
        "sizes are in metres; did you write millimetres?)\n"
    )
    # sizes that fit the range but not the mass: 2 kg in 20 x 10 x 5 m is 2e-3 kg/m³
    big = tmp_path / "big.toml"
    big.write_text(
        BOX.replace("size = [0.20, 0.10, 0.05]", "size = [20.0, 10.0, 5.0]")
        .replace("[0.10, 0.05, 0.025]", "[10.0, 5.0, 2.5]")
        .replace("[0.04, 0.02, 0.0]", "[4.0, 2.0, 0.0]")
        .replace("[0.16, 0.02, 0.0]", "[16.0, 2.0, 0.0]")
        .replace("[0.10, 0.08, 0.0]", "[10.0, 8.0, 0.0]")
        .replace("[0.04, 0.0, 0.025]", "[4.0, 0.0, 2.5]")
        .replace("[0.16, 0.0, 0.025]", "[16.0, 0.0, 2.5]")
        .replace("[0.0, 0.05, 0.025]", "[0.0, 5.0, 2.5]")
    )
    code, out, err = run(capsys, "validate", big)
    assert code == 0 and out.startswith(f"{big}: ok (")
    assert err == (
        f"{big}: workpiece.mass: warning: the part's density is 0.002 kg/m³, far outside solids (5 to 50000 kg/m³); "
        "units are metres and kilograms (is the file in millimetres or grams?)\n"
    )


def test_classify_many_wrenches_summarised_and_written(capsys, tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    W = np.zeros((60, 6))
    W[:, 0] = rng.uniform(-20, 20, 60)
    csv = tmp_path / "w.csv"
    csv.write_text("\n".join(",".join(f"{x:g}" for x in w) for w in W) + "\n")
    rows = tmp_path / "rows.csv"
    code, out, _ = run(capsys, "classify", "--wrenches", csv, "--out", rows)
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "box-3-2-1: 60 wrenches on contacts B1, B2, B3" and len(lines) <= 10
    counts = {line.split()[0]: int(line.split()[1]) for line in lines[1:] if line.startswith("  ")}
    assert sum(counts.values()) == 60
    # |Fx| below μ m g = 0.25 * 2 * 9.81 = 4.905 N is held by friction on the base; above, it slides
    held = int(np.sum(np.abs(W[:, 0]) < 0.25 * 2 * 9.81))
    assert counts.get("jammed", 0) + counts.get("held", 0) == held
    table = rows.read_text().splitlines()
    assert table[0] == "index,Fx,Fy,Fz,Tx,Ty,Tz,mode,margin,certificate" and len(table) == 61


def test_map_axes_defaults_aliases_and_units(capsys, tmp_path: Path) -> None:
    code, out, err = run(capsys, "map", PROBLEMS / "disk-2d.toml", "--n", "2", "--out", tmp_path / "d.png", "--json")
    assert code == 0, err
    assert strict_json(out)["axes"] == ["Fx", "Mz"]
    code, out, err = run(
        capsys, "map", "--axes", "Fx,Mz", "--n", "2", "--wrench", "0,0,-5,0,0,0", "--out", tmp_path / "b.png", "--json"
    )
    assert code == 0, err
    summary = strict_json(out)
    assert summary["axes"] == ["Fx", "Tz"] and summary["base_wrench"] == [0, 0, -5, 0, 0, 0]
    from fixplan.mapping import axis_unit

    assert (axis_unit("Fx"), axis_unit("Tz"), axis_unit("Mz")) == ("N", "N·m", "N·m")


def test_validation_at_the_cap_is_fast(capsys, tmp_path: Path) -> None:
    """100 locators (the cap), most of them off the part: each of goal finding's 49 starts stops at a least-squares minimum."""
    head = BOX.split("[[locator]]")[0]
    rows = [
        f'[[locator]]\nname = "L{i}"\nposition = [{0.002 * (i % 50):.3f}, {0.01 * (i // 50):.3f}, -0.0{i % 7}]\n'
        "friction = 0.2\n"
        for i in range(limits.MAX_ENTRIES)
    ]
    path = tmp_path / "cap.toml"
    path.write_text(head + "\n".join(rows))
    t0 = time.perf_counter()
    code, _, err = run(capsys, "validate", path)
    assert time.perf_counter() - t0 < 15  # was 60 s for 50 locators: 20 line-search halvings x 100 iterations
    assert code == 2 and f"{path}: locator: goal finding did not converge from 49 starts (largest gap " in err


@pytest.mark.parametrize("name", ["[/x] [bold]b", "a\nb"])
def test_scene_names_print_as_written(capsys, tmp_path: Path, name: str) -> None:
    """Rich markup in a scene name is text (it failed with MarkupError, exit 3); control characters are refused."""
    path = tmp_path / "f.toml"
    path.write_text(BOX.replace('name = "box-3-2-1"', f"name = {json.dumps(name)}"))
    code, out, err = run(capsys, "classify", path, "--wrench", "0,0,0,0,0,0")
    if name.isprintable():
        assert code == 0 and f"{name}: contacts B1, B2, B3, S1, S2, E1" in out
    else:
        assert code == 2 and err == (
            f"{path}: scene.name: expected a printable name of at most 200 characters (no newlines or control codes)\n"
        )


def test_margins_are_range_checked(capsys) -> None:
    code, _, err = run(capsys, "search", "--motion", "0.1,0,0,0,0,0", "--min-margin", "1e300")
    assert code == 2 and err == "fixplan: --min-margin is 1e+300 (expected a force [N] in [0, 1e+06])\n"
    code, _, err = run(capsys, "solve", "--margin", "1e300", "--no-verify")
    assert code == 2 and "--margin" in err and "1000000" in err and len(err.splitlines()) == 1


def test_a_hard_link_to_the_input_is_refused_as_an_output(capsys, tmp_path: Path) -> None:
    # a hard link has its own path: comparing resolved paths let 'solve FILE --out LINK --force' eat FILE
    fixture = tmp_path / "box.toml"
    fixture.write_text(BOX)
    link = tmp_path / "plan.json"
    os.link(fixture, link)
    code, _, err = run(capsys, "solve", fixture, "--out", link, "--force", "--no-verify")
    assert code == 2 and f"--out {link} is the same file as FILE {fixture}" in err
    assert fixture.read_text() == BOX


def test_outputs_are_renamed_into_place_never_written_through_a_link(tmp_path: Path) -> None:
    target = tmp_path / "someone-elses.txt"
    target.write_text("keep me")
    link = tmp_path / "out.txt"
    link.symlink_to(target)
    write_output(link, lambda p: p.write_text("new"))
    assert target.read_text() == "keep me"  # the link was replaced, not written through
    assert not link.is_symlink() and link.read_text() == "new"

    # a failed write leaves neither a half file nor its temporary beside it
    def half(p: Path) -> None:
        p.write_text("half")
        raise OSError(errno.EIO, "Input/output error")

    with pytest.raises(InputError, match="cannot write"):
        write_output(tmp_path / "x.csv", half)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt", "someone-elses.txt"]
