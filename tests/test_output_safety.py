"""Outputs never lose a user's byte, and standard output failing is one line.

- An output that is a hard link to an input was written through it (``box.toml`` held the
  CSV). Every output now goes through :func:`fixplan.files.write_output` (a temporary file renamed
  into place) and is refused when it is the same file (device and inode) as any input the
  command read, whatever option named the input, the bundled fixture included.
- A full disk left a 0-byte or partial output. The temporary file is flushed to the disk
  before the rename and removed on failure; the target keeps what it held.
- Standard output on ``/dev/full`` (or a closed pipe) was an ``OSError`` and exit 3.
- With ``--json``, whatever a library prints (Python, a thread, file descriptor 1, a child
  process) goes to stderr; stdout is the one document.

Size-limited places are made with ``RLIMIT_FSIZE`` (the kernel refuses a write past the limit with
``EFBIG`` partway through, as a full disk does with ``ENOSPC``); the kernels are compiled before
(``warm``), so that only the output hits the limit.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import resource
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import CLI, PROBLEMS

import fixplan
from fixplan.cli import main
from fixplan.errors import InputError
from fixplan.files import CommandStreams, read_user_text, write_output, write_text

BOX = PROBLEMS / "box-3-2-1.toml"


def run(capsys, *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert "Traceback" not in err and "internal error" not in err, err
    return code, out, err


def leftovers(folder: Path) -> list[str]:
    """Temporary files of write_output left in ``folder`` (hidden ``.NAME.PID-HEX.tmpSUFFIX``)."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(".") and ".tmp" in p.name)


@contextlib.contextmanager
def file_size_limit(nbytes: int):
    """Every file this process writes stops at ``nbytes``: past it a write fails with EFBIG (Python ignores SIGXFSZ)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (nbytes, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """Run each command once, so that no kernel is compiled (and cached to disk) under a size limit."""
    folder = tmp_path_factory.mktemp("warm")
    for args in (
        ["classify", BOX, "--wrench", "1,0,0,0,0,0", "--out", folder / "c.csv"],
        ["simulate", BOX, "--duration", "0.01", "--out", folder / "s.csv"],
        ["map", BOX, "--n", "3", "--out", folder / "m.png"],
        ["solve", BOX, "--no-verify", "--out", folder / "p.json", "--report", folder / "r.md"],
        ["view", BOX, "--out", folder / "v.html"],
    ):
        assert main([str(a) for a in args]) in (0, 1)
    return folder


@pytest.fixture
def user(tmp_path: Path) -> Path:
    """A user's folder: a fixture, a wrench list, a plan."""
    (tmp_path / "box.toml").write_bytes(BOX.read_bytes())
    (tmp_path / "w.csv").write_text("1,0,0,0,0,0\n0,1,0,0,0,0\n")
    return tmp_path


# -- a hard link to an input -----------------------------------------------------------------------
# (command line, the input the output is a hard link of, the output's name); "{out}" is the link
HARD_LINK_CASES = {
    "classify FILE": (["classify", "box.toml", "--wrench", "1,0,0,0,0,0", "--out", "{out}"], "box.toml", "o.csv"),
    "classify --wrenches": (["classify", "box.toml", "--wrenches", "w.csv", "--out", "{out}"], "w.csv", "o.csv"),
    "simulate": (["simulate", "box.toml", "--duration", "0.01", "--out", "{out}"], "box.toml", "o.csv"),
    "solve --out": (["solve", "box.toml", "--no-verify", "--out", "{out}"], "box.toml", "o.json"),
    "solve --report": (["solve", "box.toml", "--no-verify", "--report", "{out}"], "box.toml", "r.md"),
    "solve figure": (["solve", "box.toml", "--no-verify", "--report", "r.md"], "box.toml", "r.png"),
    "view": (["view", "box.toml", "--out", "{out}"], "box.toml", "o.html"),
    "map image": (["map", "box.toml", "--n", "3", "--out", "{out}"], "box.toml", "o.png"),
    "map CSV": (["map", "box.toml", "--n", "3", "--out", "o.png"], "box.toml", "o.csv"),
    "haptic --record": (["haptic", "box.toml", "--no-browser", "--record", "{out}"], "box.toml", "o.json"),
}


@pytest.mark.parametrize("case", sorted(HARD_LINK_CASES))
def test_an_output_hard_linked_to_an_input_is_refused_and_the_input_kept(capsys, user, case):
    args, source, name = HARD_LINK_CASES[case]
    before = (user / source).read_bytes()
    os.link(user / source, user / name)
    here = os.getcwd()
    os.chdir(user)
    try:
        code, out, err = run(capsys, *[a.replace("{out}", name) for a in args], "--force")
    finally:
        os.chdir(here)
    assert code == 2, err
    assert len(err.splitlines()) == 1 and "is the same file as" in err and source in err, err
    assert (user / source).read_bytes() == before
    assert os.stat(user / source).st_ino == os.stat(user / name).st_ino  # nothing replaced either
    assert leftovers(user) == []


def test_a_hard_link_to_the_bundled_fixture_is_refused_too(capsys, tmp_path):
    """No FILE: the default fixture is an input all the same (main renamed over the link and exited 0)."""
    default = fixplan.default_fixture_path()
    link = tmp_path / "out.csv"
    try:
        os.link(default, link)
    except OSError:
        pytest.skip("the package is on another file system")
    before = default.read_bytes()
    code, _, err = run(capsys, "classify", "--wrench", "1,0,0,0,0,0", "--out", link, "--force")
    assert code == 2 and f"is the same file as the input {default}" in err, err
    assert default.read_bytes() == before and os.stat(link).st_ino == os.stat(default).st_ino


def test_write_output_refuses_an_input_linked_after_the_checks(tmp_path):
    """The check runs at the write itself: a link made while the command worked is refused as well."""
    source = tmp_path / "in.toml"
    source.write_text("x = 1\n")
    with CommandStreams(document=False):
        read_user_text(source, expected="a file")
        os.link(source, tmp_path / "late.csv")
        with pytest.raises(InputError, match=r"late.csv is the same file as the input .*in.toml"):
            write_text(tmp_path / "late.csv", "a,b\n")
    assert source.read_text() == "x = 1\n" and leftovers(tmp_path) == []
    # outside a command nothing is remembered; the rename still never writes through the link
    write_text(tmp_path / "late.csv", "a,b\n")
    assert source.read_text() == "x = 1\n" and (tmp_path / "late.csv").read_text() == "a,b\n"


def test_a_replaced_output_keeps_its_permissions_and_a_long_name_fits(tmp_path):
    private = tmp_path / "private.json"
    private.write_text("old")
    private.chmod(0o600)
    write_text(private, "new")
    assert private.read_text() == "new" and stat.S_IMODE(private.stat().st_mode) == 0o600  # main: 0o644
    long = tmp_path / ("p" * 250 + ".csv")  # 254 bytes: the temporary name must still fit in 255
    write_text(long, "a\n")
    assert long.read_text() == "a\n" and leftovers(tmp_path) == []


# -- a full disk ------------------------------------------------------------------------------
def test_a_disk_full_at_the_flush_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    """ENOSPC is often reported only when the data reaches the disk: the write is flushed before the rename."""
    target = tmp_path / "plan.json"
    target.write_text("the user's old plan")

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(InputError, match=rf"^cannot write {target}: no space left on the device$"):
        write_text(target, "{}" * 1000)
    assert target.read_text() == "the user's old plan" and leftovers(tmp_path) == []


def test_a_writer_failing_partway_leaves_nothing_under_the_users_name(tmp_path):
    target = tmp_path / "new.csv"

    def half(path: Path) -> None:
        path.write_text("a,b\n1,")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(InputError, match="no space left on the device"):
        write_output(target, half)
    assert not target.exists() and leftovers(tmp_path) == []


# one command per writer: plain text, a CSV written row by row, a matplotlib figure, an HTML page
FULL_DISK_CASES = {
    "text (solve --out)": (["solve", "box.toml", "--no-verify", "--out", "o.json"], ["o.json"]),
    "text (generate)": (["generate", "box-321", "--count", "1", "--out", "."], ["box-321-s0-000.toml"]),
    "CSV (classify)": (["classify", "box.toml", "--wrenches", "w.csv", "--out", "o.csv"], ["o.csv"]),
    "CSV (simulate)": (["simulate", "box.toml", "--duration", "0.05", "--out", "o.csv"], ["o.csv"]),
    "figure (map)": (["map", "box.toml", "--n", "8", "--out", "o.png"], ["o.png", "o.csv"]),
    "figure (solve --report)": (["solve", "box.toml", "--no-verify", "--report", "r.md"], ["r.png", "r.md"]),
    "page (view)": (["view", "box.toml", "--out", "o.html"], ["o.html"]),
}


@pytest.mark.parametrize("case", sorted(FULL_DISK_CASES))
def test_a_full_place_fails_every_writer_with_exit_2_and_keeps_the_old_files(capsys, user, warm, case):
    args, outputs = FULL_DISK_CASES[case]
    for name in outputs:
        (user / name).write_text("OLD")
    here = os.getcwd()
    os.chdir(user)
    try:
        with file_size_limit(40):  # every output is longer: the write fails partway
            code = main([*args, "--force"])
    finally:
        os.chdir(here)
    _, err = capsys.readouterr()
    assert code == 2, err
    assert err.count("fixplan: cannot write ") == 1 and "File too large" in err, err
    for name in outputs:
        assert (user / name).read_text() == "OLD", name
    assert leftovers(user) == []


# -- standard output that cannot be written -----------------------------------------------------
def cli(*args: object, stdout: object = None, wrapper: str | None = None) -> subprocess.CompletedProcess:
    """``fixplan ARGS`` (or ``wrapper``'s script with ARGS) in a fresh interpreter, stdout buffered as in a shell."""
    cmd = [*CLI, *map(str, args)] if wrapper is None else [sys.executable, "-c", wrapper, *map(str, args)]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    return subprocess.run(
        cmd, stdout=stdout, stderr=subprocess.PIPE, text=True, timeout=300, stdin=subprocess.DEVNULL, env=env
    )


STDOUT_CASES = {
    "table": ["classify", BOX, "--wrench", "1,0,0,0,0,0"],
    "json": ["classify", BOX, "--wrench", "1,0,0,0,0,0", "--json"],
    "lines": ["validate", BOX],
    "long text": ["schema"],
    "help": ["--help"],
    "json list": ["generate", "--list", "--json"],
}


@pytest.mark.parametrize("case", sorted(STDOUT_CASES))
def test_stdout_on_dev_full_is_exit_2_and_one_line(case):
    with open("/dev/full", "w") as full:
        proc = cli(*STDOUT_CASES[case], stdout=full)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == "fixplan: cannot write to standard output: no space left on the device\n"


def test_a_closed_pipe_is_exit_2_and_one_line_without_traceback():
    read, write = os.pipe()
    os.close(read)
    try:
        proc = cli("schema", stdout=write)
    finally:
        os.close(write)
    assert proc.returncode == 2
    assert proc.stderr == "fixplan: cannot write to standard output: the reader closed the pipe\n"


# a library holding the interpreter's own stdout: its buffer is flushed only when the interpreter exits
LATE_WRITER = """
import sys
from fixplan.cli import main
sys.__stdout__.write("a library's last words, still buffered at exit\\n")
sys.exit(main(sys.argv[1:]))
"""


def test_a_failure_at_the_last_flush_is_one_line_not_exception_ignored():
    with open("/dev/full", "w") as full:
        proc = cli("validate", BOX, stdout=full, wrapper=LATE_WRITER)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr == "fixplan: cannot write to standard output: no space left on the device\n"


# -- --json owns stdout -------------------------------------------------------------------------
NOISY = """
import os, subprocess, sys, threading
import fixplan.jamming
from fixplan.cli import main

classify = fixplan.jamming.classify

def noisy(*args, **kwargs):
    print("(library) hello from Python")
    t = threading.Thread(target=lambda: print("(library) hello from a thread"))
    t.start()
    t.join()
    os.write(1, b"(library) hello on file descriptor 1\\n")
    subprocess.run([sys.executable, "-c", "print('(library) hello from a child process')"], check=True)
    return classify(*args, **kwargs)

fixplan.jamming.classify = noisy
sys.exit(main(sys.argv[1:]))
"""


def test_json_stdout_is_one_document_while_libraries_print():
    proc = cli("classify", BOX, "--wrench", "1,0,0,0,0,0", "--json", stdout=subprocess.PIPE, wrapper=NOISY)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)  # exactly one document: any other line would make this fail
    assert doc["results"][0]["mode"] in ("jammed", "held", "separates")
    for source in ("Python", "a thread", "file descriptor 1", "a child process"):
        assert f"(library) hello from {source}" in proc.stderr or f"(library) hello on {source}" in proc.stderr
    # without --json the same output stays on stdout
    plain = cli("classify", BOX, "--wrench", "1,0,0,0,0,0", stdout=subprocess.PIPE, wrapper=NOISY)
    assert "(library) hello from a child process" in plain.stdout and plain.stderr == ""


# -- one way to write -------------------------------------------------------------------------
def _writer_calls(tree):  # -> list of (line, what)
    import ast

    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Name) and func.id == "open":
            mode = (
                node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"), None)
            )
            if isinstance(mode, ast.Constant) and isinstance(mode.value, str) and set(mode.value) & set("wax+"):
                found.append((node, f"open(..., {mode.value!r})"))
        elif isinstance(func, ast.Attribute) and func.attr in (
            "savefig",
            "write_text",
            "write_bytes",
            "savetxt",
            "tofile",
        ):
            found.append((node, f".{func.attr}(...)"))
        elif isinstance(func, ast.Attribute) and func.attr == "File" and len(node.args) > 1:
            mode = node.args[1]
            if not (isinstance(mode, ast.Constant) and mode.value == "r"):
                found.append((node, "h5py.File(..., mode)"))
    return found


def test_every_writer_in_the_package_goes_through_write_output():
    """A file is written only by a function handed to files.write_output (files.py itself excepted).

    The writers found by the issue wrote to the path they were given (map, trajectory, figure,
    page); this keeps a new one from doing so: its open/savefig/write_text must sit in a function
    (or lambda) passed to ``write_output``.
    """
    import ast

    package = Path(fixplan.__file__).parent
    bad = []
    for path in sorted(package.rglob("*.py")):
        if path.name == "files.py" and path.parent == package:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
        handed: set[str] = set()
        lambdas: set[ast.AST] = set()
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Call)
                and getattr(node.func, "id", getattr(node.func, "attr", None)) == "write_output"
            ):
                for arg in node.args[1:]:
                    if isinstance(arg, ast.Name):
                        handed.add(arg.id)
                    elif isinstance(arg, ast.Lambda):
                        lambdas.add(arg)
        for call, what in _writer_calls(tree):
            node, ok = call, False
            while node in parents:
                node = parents[node]
                if node in lambdas or (isinstance(node, ast.FunctionDef) and node.name in handed):
                    ok = True
                    break
            if not ok:
                bad.append(f"{path.relative_to(package.parent)}:{call.lineno}: {what}")
    assert bad == [], "writes outside files.write_output:\n" + "\n".join(bad)
