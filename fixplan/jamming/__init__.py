"""Jamming analysis: what a push does to a part at rest in its contacts, and which push won't jam.

- :func:`classify` — the mode per wrench (held, jammed, separates, slides, rolls, indeterminate);
- :func:`search_wrench` — the non-jamming wrench for a desired motion (docs/math.md program 2);
  :func:`search_wrench_in` the same for a contact set already built (motion of the centre of mass);
- :func:`can_wedge` — whether the contacts can hold self-equilibrated forces.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from fixplan.errors import InputError
from fixplan.jamming.classify import MODES, Classification, Classifier, wrench_array
from fixplan.jamming.search import WrenchSearch, search_wrench, search_wrench_in
from fixplan.jamming.wedge import can_wedge, wedge_force
from fixplan.locating import contact_set
from fixplan.settings import DEFAULT, Settings

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose

__all__ = [
    "MODES",
    "Classification",
    "Classifier",
    "WrenchSearch",
    "can_wedge",
    "classify",
    "search_wrench",
    "search_wrench_in",
    "wedge_force",
]


def classify(
    fixture: Fixture,
    wrenches: ArrayLike | Sequence[Sequence[float]],
    contacts: Sequence[str] | None = None,
    at: ArrayLike | None = None,
    *,
    pose: Pose | str | None = None,
    backend: str = "clarabel",
    settings: Settings | None = None,
    jobs: int | None = None,
    progress: Callable[[int], None] | None = None,
    as_json: bool | str = False,
) -> list[Classification]:
    """Classify each applied wrench (in addition to gravity) for the workpiece at rest.

    Parameters
    ----------
    fixture : Fixture
        A loaded fixture (:func:`fixplan.load`).
    wrenches : array_like, (N, 6) or (6,) in 3D, (N, 3) or (3,) in 2D
        ``Fx,Fy,Fz,Tx,Ty,Tz`` (2D: ``Fx,Fy,Mz``) about the body-frame origin, world axes.
    contacts : sequence of str, optional
        Contact names; default: the locators touching at ``pose`` plus explicit contacts.
    at : array_like, optional
        World point the moments are taken about, instead of the body-frame origin.
    pose : Pose or "start" or "goal", optional
        Where the workpiece is (default: the start pose).
    backend : {"clarabel", "cvxpy"}
        The fast matrix path or the cvxpy reference model.
    settings : Settings, optional
        A profile (:mod:`fixplan.settings`) whose ``tolerances`` say what balanced and slipping
        mean and whose ``witness`` when a motion witness is accepted; default: the fixture's
        tolerances and the default profile's witness settings.
    jobs : int, optional
        Worker processes for large batches (default: the CPUs available; 1 = in-process).
    progress : callable, optional
        Called with the number of wrenches finished since the last call.
    as_json : bool or "text"
        Return each result's JSON dictionary instead (built in the worker processes; what the
        CLI prints), or with ``"text"`` its compact JSON text, encoded in the workers too.

    Returns
    -------
    list of Classification
        One per wrench, in input order.
    """
    from fixplan.jamming.batch import classify_batch  # its process pool (and logging) only when classifying

    W = wrench_array(wrenches, fixture.ndof)
    cs = contact_set(fixture, pose, contacts)
    if at is not None:
        at = np.asarray(at, dtype=float)
        if at.shape != (fixture.dimension,):
            raise InputError(
                f"classify.at expects {fixture.dimension} coordinates, got {at.shape[0] if at.ndim else 1}"
            )
    tol = fixture.tolerances if settings is None else settings.tolerances
    witness = DEFAULT.witness if settings is None else settings.witness
    W_com = np.array([cs.wrench_about_com(w, at) for w in W])
    if len(cs) == 0:
        Classifier(cs, fixture.gravity_wrench(), tolerances=tol, backend=backend)  # raises the clear error
    return classify_batch(
        cs, fixture.gravity_wrench(), tol, backend, W_com, W, jobs=jobs, progress=progress, as_json=as_json,
        witness=witness,
    )  # fmt: skip
