"""fixplan: plan how a workpiece is loaded into a fixture without jamming.

The public API is small and imported lazily, so ``import fixplan`` stays fast and does not
pull in cvxpy, CasADi or numba until they are needed.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

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
    "Settings": ("fixplan.settings", "Settings"),
}

__all__ = sorted([*_LAZY, "__version__"])


def _version() -> str:
    """The installed version, written once in pyproject.toml.

    Read on first use: importing ``importlib.metadata`` costs 20 ms that a command which never
    prints the version should not pay.
    """
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fixplan")
    except PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        value = _version()
        globals()[name] = value
        return value
    try:
        module_name, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'fixplan' has no attribute {name!r}") from None
    value = getattr(import_module(module_name), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
