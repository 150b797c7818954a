"""The model apart from its loader: the located pose is a field computed at load, no import loop."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

import fixplan
from fixplan.errors import InfeasibleError
from fixplan.locating import locator_gaps, with_goal
from fixplan.spatial import Pose


def test_the_goal_is_computed_at_load_as_a_field():
    fx = fixplan.load(fixplan.default_fixture_path())
    assert fx.goal_pose is not None and fx.goal is fx.goal_pose
    # every locator touches there (the 3-2-1 box: its centre at half its size, axes aligned)
    assert np.max(np.abs(locator_gaps(fx.workpiece, fx.goal, fx.locators))) <= 1e-12
    assert np.allclose(fx.goal.p_world, [0.1, 0.05, 0.025], atol=1e-12)


def test_the_model_does_not_import_the_loader_or_the_locating():
    code = "import sys, fixplan.model; print(sorted(m for m in sys.modules if m in ('fixplan.fixture', 'fixplan.locating')))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_changed_model_is_located_again():
    """Every locator moved by δ: the located pose moves by δ (same rotation)."""
    fx = fixplan.load(fixplan.default_fixture_path())
    delta = np.array([0.01, -0.02, 0.003])
    moved = dataclasses.replace(
        fx,
        locators=tuple(dataclasses.replace(loc, p_world=loc.p_world + delta) for loc in fx.locators),
        start=Pose(fx.start.R_world_body, fx.start.p_world + delta),
        goal_pose=None,
    )
    with pytest.raises(InfeasibleError, match="without locating it"):
        moved.goal  # noqa: B018 - a model built by hand has no goal until it is located
    relocated = with_goal(moved)
    assert np.allclose(relocated.goal.p_world, fx.goal.p_world + delta, atol=1e-9)
    assert np.allclose(relocated.goal.R_world_body, fx.goal.R_world_body, atol=1e-9)


def test_a_fixture_that_is_not_full_has_no_goal():
    fx = fixplan.load(fixplan.default_fixture_path())
    partial = dataclasses.replace(fx, locators=fx.locators[:3], goal_pose=None)
    with pytest.raises(InfeasibleError, match="needs a full fixture"):
        partial.goal  # noqa: B018
    with pytest.raises(InfeasibleError, match="needs a full fixture"):
        with_goal(partial)
