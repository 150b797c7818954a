"""Role codes of a contact in a witness system, shared by :mod:`.sliding` and its compiled kernels.

A module of its own so that :mod:`.sliding` can name them without importing numba (the kernels
may come from :mod:`fixplan.aot`'s extension).
"""

SLIDE, STICK, OPEN = 0, 1, 2  # sliding (friction at its limit), sticking (no relative acceleration), open
