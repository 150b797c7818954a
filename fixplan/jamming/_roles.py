"""Role codes of a contact in a witness system, shared by :mod:`.sliding` and its compiled kernels.

A module of its own so that :mod:`.sliding` can name them without importing numba (the kernels
may come from :mod:`fixplan.aot`'s extension).

They are a motion witness's *roles* (what the witness asks of a contact), named ``ROLE_*`` so they
cannot be mistaken for the engine's one-contact *regimes* (:mod:`fixplan.engine.local`: ``OPEN``,
``STICK``, ``SLIDE``, ``FAILED``, numbered otherwise) nor for its solve statuses
(:mod:`fixplan.engine.status`).
"""

ROLE_SLIDING = 0  # kept, friction at its limit opposing the slip
ROLE_STICKING = 1  # kept, no relative acceleration
ROLE_OPENING = 2  # no force, no equation (its opening is checked afterwards)
