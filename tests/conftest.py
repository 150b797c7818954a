"""Shared test helpers: paths, the optional ../shared folder, seeded RNG, the CLI, the box on three supports.

Test modules import the plain helpers (``from conftest import PROBLEMS, run_cli``); pytest puts
this folder on ``sys.path`` when it loads this file.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import fixplan
from fixplan.robot_file import names_robot_data, robot_data_installed

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"
SHARED = ROOT.parent / "shared"
ROBOT_DATA_MISSING: str | None = (
    None
    if robot_data_installed()
    else "example-robot-data is not installed (the optional extra fixplan[robots]: make install installs it, "
    "or pip install -e '.[robots]'): the library's Panda and UR5 problems need it"
)
"""Why the fixtures that name a robot of example-robot-data are skipped here (None: they run)."""


def needs_robot_data(path: Path) -> bool:
    """A fixture file naming a robot of example-robot-data while that extra is missing: its tests skip."""
    return ROBOT_DATA_MISSING is not None and names_robot_data(path) is not None


def library(folder: Path = PROBLEMS) -> list[Path]:
    """The fixture files of a library folder (not its ``expected.toml``), less those :func:`needs_robot_data`."""
    return sorted(p for p in folder.glob("*.toml") if p.name != "expected.toml" and not needs_robot_data(p))


def library_params(folder: Path = PROBLEMS) -> list[Any]:
    """Every fixture file of a library folder as a pytest parameter, those that need the missing extra skipped."""
    marks = pytest.mark.skip(reason=str(ROBOT_DATA_MISSING))
    return [
        pytest.param(p, marks=marks) if needs_robot_data(p) else p
        for p in sorted(folder.glob("*.toml"))
        if p.name != "expected.toml"
    ]


CLI = [sys.executable, "-c", "import sys; from fixplan.cli import main; sys.exit(main())"]
"""``fixplan`` as a fresh process, from this checkout's package (not an installed entry point)."""


def run_cli(
    *args: str, timeout: float | None = 600, cwd: Path | None = None, check_rc: int | None = None
) -> subprocess.CompletedProcess[str]:
    """``fixplan ARGS`` in a fresh process; stdout and stderr captured as text.

    ``check_rc`` asserts the exit status (the message is stderr).
    """
    proc = subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=cwd)
    if check_rc is not None:
        assert proc.returncode == check_rc, proc.stderr
    return proc


def box_on_three_supports(
    mu: float = 0.3,
    *,
    mass: float = 2.0,
    gravity: Sequence[float] = (0.0, 0.0, -9.81),
    torsion: float = 0.0,
    simulation: dict[str, float] | None = None,
    extra: str = "",
) -> fixplan.Fixture:
    """A 0.2×0.1×0.05 box (``mass`` [kg]) resting on three point supports B1–B3 under its −z face.

    The supports are at ``(∓0.06, −0.03, 0)`` and ``(0, 0.03, 0)``: the centre of mass, above
    ``(0, 0)``, is inside their triangle. ``mu`` and ``torsion`` [m] apply to all three;
    ``simulation`` fills the ``[simulation]`` table (``timestep``, ``tolerance``,
    ``restitution``); ``extra`` is appended TOML (more locators).
    """
    tors = f"torsion = {torsion}\n" if torsion else ""
    locators = "".join(
        f'[[locator]]\nname = "B{i}"\nposition = [{x}, {y}, 0.0]\nfriction = {mu}\n{tors}'
        for i, (x, y) in enumerate([(-0.06, -0.03), (0.06, -0.03), (0.0, 0.03)], 1)
    )
    g = "[" + ", ".join(f"{x:.17g}" for x in gravity) + "]"
    sim = "".join(f"{k} = {v}\n" for k, v in (simulation or {}).items())
    return fixplan.loads(
        f"""format = 1
[scene]
name = "box-3-supports"
gravity = {g}
[workpiece]
shape = "box"
size = [0.2, 0.1, 0.05]
mass = {mass}
start = {{ position = [0.0, 0.0, 0.025] }}
{"[simulation]" if sim else ""}
{sim}{locators}{extra}"""
    )


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


# -- plans solved once per session ---------------------------------------------------------------
# Several modules read the same plans; each is solved once for the whole run (a verified solve of
# the default box takes seconds) instead of once per module or per test. The tests only read them;
# a test that edits a plan's JSON edits its own copy.
@pytest.fixture(scope="session")
def default_fixture() -> fixplan.Fixture:
    return fixplan.load(fixplan.default_fixture_path())


@pytest.fixture(scope="session")
def default_plan(default_fixture: fixplan.Fixture):  # -> PlanResult
    """``fixplan.solve`` of the default box, verified in the simulated haptic loop."""
    return fixplan.solve(default_fixture)


@pytest.fixture(scope="session")
def default_plan_unverified(default_fixture: fixplan.Fixture):  # -> PlanResult
    """``fixplan.solve(..., run_verification=False)`` of the default box."""
    return fixplan.solve(default_fixture, run_verification=False)


@pytest.fixture(scope="session")
def jams_plan():  # -> PlanResult
    """``fixplan.solve`` of ``problems/naive-order-jams.toml`` (2D, on B1 alone), verified."""
    return fixplan.solve(fixplan.load(PROBLEMS / "naive-order-jams.toml"))


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """The ../shared folder beside the checkout; tests that need it skip without it."""
    if not (SHARED / "data").is_dir():
        pytest.skip(f"../shared is absent ({SHARED}); a user's clone has none")
    return SHARED


@pytest.fixture(scope="session")
def fclib_dir(shared_dir: Path) -> Path:
    path = shared_dir / "data" / "fclib"
    if not any(path.glob("*.hdf5")):
        pytest.skip(f"no FCLib problems in {path}")
    return path
