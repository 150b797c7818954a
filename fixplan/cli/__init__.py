"""The ``fixplan`` command line.

Every command validates its fixture first. Bad input (a malformed file, a wrench of the wrong
length, an unknown contact) prints clear one-line errors on stderr and exits with status 2,
never a traceback. ``--json`` prints exactly one JSON object on stdout; progress and logs go
to stderr. Files are never overwritten without ``--force``.

The commands live by group (:mod:`.analysis`, :mod:`.planning`, :mod:`.tools`, :mod:`.haptic`)
and only parse arguments, call the library, print and choose the exit code; :mod:`._app` holds
the application, the shared options and parsing, and :func:`main` (the console script). Heavy
packages (cvxpy, casadi, plotly, viser, dask) are imported inside the commands that need them.
"""

from __future__ import annotations

from fixplan.cli._app import app, main

# the command modules register their commands on app, in the order --help lists them
from fixplan.cli import analysis, planning, tools, haptic, clamp  # noqa: E402, F401, I001  isort: skip

__all__ = ["app", "main"]
