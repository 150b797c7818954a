"""The contact forces that hold the part at rest under gravity at its start pose (no push)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from fixplan.model import Fixture

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RestForces:
    """What gravity alone does to the part at its start pose, and the contact forces when it rests.

    Attributes
    ----------
    mode : str
        :func:`fixplan.classify`'s mode under gravity with no push (``held``, ``jammed``, ``slides``, ...).
    forces_world_N : (n, d) array or None
        Force on the workpiece at each locator (fixture order; 0 where a locator does not touch),
        world axes [N]; None unless the part is ``held`` or ``jammed`` (it does not rest).
    extra_forces : tuple of (point_world, force_world_N)
        Forces at the explicit ``[[contact]]`` entries.
    """

    mode: str
    forces_world_N: FloatArray | None
    extra_forces: tuple[tuple[FloatArray, FloatArray], ...] = ()


def rest_forces(fixture: Fixture) -> RestForces | None:
    """The contact forces at rest under gravity at the start pose; None when nothing touches there.

    Raises what :func:`fixplan.classify` raises (a :class:`~fixplan.errors.FixplanError`).
    """
    from fixplan.jamming import classify
    from fixplan.locating import contact_set

    cs = contact_set(fixture, "start")
    if not cs.contacts:
        return None
    # as_json: each result is its JSON dictionary, with the contact forces in world axes
    result = cast(dict[str, Any], classify(fixture, np.zeros((1, fixture.ndof)), pose="start", jobs=1, as_json=True)[0])
    mode = str(result["mode"])
    if mode not in ("held", "jammed"):
        return RestForces(mode, None)
    names = [loc.name for loc in fixture.locators]
    F = np.zeros((len(names), fixture.dimension))
    extra = []
    points = {c.name: c.point_world for c in cs.contacts}
    for name, f in result["contact_forces"].items():
        fw = np.asarray(f["force_world"], dtype=float)
        if name in names:
            F[names.index(name)] = fw
        else:
            extra.append((np.asarray(points[name], dtype=float), fw))
    return RestForces(mode, F, tuple(extra))
