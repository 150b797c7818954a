"""fixplan: plan how a workpiece is loaded into a fixture without jamming.

The public API is small and imported lazily, so ``import fixplan`` stays fast and does not
pull in cvxpy, CasADi or numba until they are needed.
"""

from __future__ import annotations

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from typing import Any

try:  # the version is written once, in pyproject.toml
    __version__ = version("fixplan")
except PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
    __version__ = "0+unknown"

_LAZY = {
    "load": ("fixplan.fixture", "load"),
    "loads": ("fixplan.fixture", "loads"),
    "Fixture": ("fixplan.model", "Fixture"),
    "default_fixture_path": ("fixplan.fixture", "default_fixture_path"),
    "classify": ("fixplan.jamming", "classify"),
    "search_wrench": ("fixplan.jamming", "search_wrench"),
    "contact_set": ("fixplan.locating", "contact_set"),
    "Simulator": ("fixplan.engine.simulator", "Simulator"),
    "WrenchSchedule": ("fixplan.engine.simulator", "WrenchSchedule"),
    "solve": ("fixplan.planner.solve", "solve"),
    "FixplanError": ("fixplan.errors", "FixplanError"),
    "FixtureError": ("fixplan.errors", "FixtureError"),
    "InputError": ("fixplan.errors", "InputError"),
    "InfeasibleError": ("fixplan.errors", "InfeasibleError"),
    "SolverError": ("fixplan.errors", "SolverError"),
    "Tolerances": ("fixplan.settings", "Tolerances"),
    "Settings": ("fixplan.settings", "Settings"),
}

__all__ = sorted([*_LAZY, "__version__"])


def __getattr__(name: str) -> Any:
    try:
        module_name, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'fixplan' has no attribute {name!r}") from None
    value = getattr(import_module(module_name), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
