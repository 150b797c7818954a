"""Deprecated: the tolerances moved to :mod:`fixplan.settings` (``Settings.tolerances``).

Kept so ``from fixplan.tolerances import Tolerances, DEFAULT`` still works; new code imports
from :mod:`fixplan.settings`.
"""

from __future__ import annotations

from fixplan.settings import DEFAULT_TOLERANCES as DEFAULT
from fixplan.settings import PROFILES as _SETTINGS_PROFILES
from fixplan.settings import Tolerances

PROFILES: dict[str, Tolerances] = {name: s.tolerances for name, s in _SETTINGS_PROFILES.items()}

__all__ = ["DEFAULT", "PROFILES", "Tolerances"]
