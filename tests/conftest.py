"""Shared test helpers: paths, the optional ../shared folder, seeded RNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"
SHARED = ROOT.parent / "shared"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(0)


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
