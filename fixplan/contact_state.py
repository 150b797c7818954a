"""A contact state: the contacts (locators, pins, bores) pressing on the part, its printed form and its debounce.

The plan is a sequence of contact states ``S_0 ⊂ S_1 ⊂ … ⊂ S_n`` (the paper's recognisable
states); the executor, the interactive session, the insertion run and a recording's re-run all
observe one from the pressed set, debounced over a dwell time (:class:`Debounce`), and every
message prints one as ``{A1, A2, B1}`` (sorted), or ``free`` when nothing presses
(:func:`format_state`).

This is the only meaning of *state* in the planner and the loops; the engine's pose and twist
are :class:`fixplan.engine.simulator.PoseTwist`.
"""

from __future__ import annotations

from collections.abc import Iterable

State = frozenset[str]  # the names of the contacts pressing on the part

FREE = "free"  # how a state with no contact reads


def format_state(state: Iterable[str], *, empty: str = FREE) -> str:
    """``{A1, A2, B1}``: the names sorted; ``empty`` (``free``) when there is none."""
    names = sorted(state)
    return "{" + ", ".join(names) + "}" if names else empty


class Debounce:
    """The observed contact state: a pressed set is accepted once it has held for ``dwell_s``.

    :meth:`observe` is called every tick with the pressed set; :attr:`observed` is the last
    accepted state (``initial`` until one is). ``slack_s`` absorbs the rounding of summed tick
    times (a set that held for the dwell to within it is accepted).
    """

    def __init__(self, dwell_s: float, *, initial: State | None = None, slack_s: float = 1e-12):
        self.dwell_s = dwell_s
        self.slack_s = slack_s
        self.observed: State | None = initial
        self.candidate: State | None = None  # a pressed set that differs from the observed one
        self.since_s = 0.0  # time the candidate was first seen [s]

    def observe(self, t: float, pressed: State) -> bool:
        """Take the pressed set at time ``t`` [s]; True when it has just been accepted as the state."""
        if pressed == self.observed:
            self.candidate = None
            return False
        if pressed != self.candidate:
            self.candidate, self.since_s = pressed, t
            return False
        if t - self.since_s + self.slack_s < self.dwell_s:
            return False
        self.observed, self.candidate = pressed, None
        return True

    def reset(self, initial: State | None = None) -> None:
        """Forget what was observed (the part was put back)."""
        self.observed, self.candidate, self.since_s = initial, None, 0.0


__all__ = ["FREE", "Debounce", "State", "format_state"]
