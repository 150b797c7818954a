"""One name and unit per quantity; modes and states as Literal types with their old values."""

from typing import get_args

import numpy as np
import pytest
from conftest import box_on_three_supports as box_on_supports

from fixplan.engine.simulator import ContactMode
from fixplan.interactive import session
from fixplan.jamming import classify
from fixplan.jamming.classify import MODES, Mode
from fixplan.planner.execute import Outcome, TransitionKind
from fixplan.planner.solve import PlanStatus


def test_mode_values_unchanged():
    """The protocol sends a verdict's index: the order is part of the contract."""
    assert MODES == get_args(Mode) == ("held", "jammed", "separates", "slides", "pivots", "rolls", "indeterminate")
    assert session.MODES == (*MODES, "free")
    assert get_args(session.Motion) == ("free", "slide", "roll", "hold", "plan", "none")
    assert get_args(session.SessionStatus) == ("reached", "jammed", "short", "diverged", "error")
    assert get_args(ContactMode) == ("open", "sticking", "sliding", "rolling")
    assert get_args(TransitionKind) == ("roll", "slide", "free")
    assert get_args(Outcome) == ("running", "reached", "failed")
    assert get_args(PlanStatus) == ("planned", "unverified", "infeasible")


def test_balance_residual_is_the_mass_weighted_residual():
    """The least ‖L⁻¹(w + Jᵀλ)‖ [N/√kg]: 0 when a push jams, > 0 when it slides; 'margin' is its alias and JSON key.

    Box of m = 2 kg on three supports (μ = 0.3) pushed along x by F: below μ m g friction balances
    it; at F = 2 μ m g friction leaves at most F − μ m g unbalanced along x, i.e. a residual of at most (F − μ m g)/√m (M = m I in translation)."""
    f = box_on_supports(mu=0.3, mass=2.0)
    limit = 0.3 * 2.0 * 9.81
    r = classify(f, [2 * limit, 0, 0, 0, 0, 0])[0]
    assert r.mode == "slides"
    assert 0.5 * limit / np.sqrt(2.0) < r.balance_residual <= limit / np.sqrt(2.0) * (1 + 1e-9)
    held = classify(f, [0.5 * limit, 0, 0, 0, 0, 0])[0]
    assert held.mode == "jammed" and held.balance_residual <= 1e-6 * limit
    assert r.margin == r.balance_residual
    assert r.to_json()["margin"] == pytest.approx(r.balance_residual)
