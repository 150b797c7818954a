"""The non-jamming wrench for a desired motion (docs/math.md "As cone programs", program 2).

Given the desired acceleration ``â`` of the workpiece (a twist rate of the body-frame origin,
world axes), every contact is sorted by what ``â`` does to it:

- kept and sliding (``G_i â = 0``, tangential ``â_t,i ≠ 0``): friction is at its limit and
  opposes the slip, ``λ_i = f_n,i (1, −μ_i â_t,i/‖â_t,i‖)`` — one unknown ``f_n,i ≥ 0``;
- kept without slip (rolling/sticking, ``J_i â = 0``): ``λ_i`` anywhere in its exact cone;
- opening (``G_i â > 0``): ``λ_i = 0``;
- penetrating (``G_i â < 0``): the motion is impossible — an input error.

With ``a = s â`` the dynamics ``M a = w + w_g + Σ J_iᵀ λ_i`` is linear in the unknowns
``(w, f_n, λ_stick, s)``, and the manipulator limits ``‖F‖ ≤ F_max``, ``‖T‖ ≤ T_max`` are
second-order cones. The program maximises the least normal force ``τ`` over the kept contacts
(the margin against losing a contact) subject to ``s ≥ 1`` (at least the requested
acceleration).

**Not jamming is a constraint of the program, not only a check afterwards.** The sliding
solution above is one motion consistent with Coulomb's law, but the same wrench can also be
balanced by contact forces in the cones whose tangential parts do not oppose the slip (rigid
bodies with friction have non-unique solutions: the body may stay wedged). Example: sliding the
located 3-2-1 box along +x on its base and side locators, base friction tilted towards the side
wall presses the side locators, whose friction tilted downwards presses the base — a wedge that
holds a little more than ``μ Σ N``. Maximising ``τ`` presses every contact as hard as the limits
allow while the drive ``M a`` stays fixed, so the best-margin wrench ends up exactly balanced:
``jammed``. The classifier (which reports ``jammed`` whenever static balance is possible) is right;
the program must exclude such wrenches. By Farkas' lemma ``w_e`` is *not* balanced iff some
motion ``y`` with ``J_i y ∈ K_i*`` at every contact (each contact separates at least ``μ`` times
as fast as it slips) has ``yᵀ w_e > 0``, and then ``yᵀ w_e / ‖y‖_M`` is a lower bound on the
classifier's margin ``min_f ‖w_e + Jᵀ f‖_{M⁻¹}``. The search takes ``ŷ`` = the ``M``-projection
of ``â`` onto that cone of motions (an SOCP; ``ŷᵀ M â > 0`` unless every push producing ``â`` is
provably balanced) and adds the second-order cone constraint
``ŷᵀ w_e ≥ ρ ‖w_e‖_{M⁻¹}`` (``ρ = jam_margin_rel``, default 10⁻³, three orders above the
classifier's ``balance_rel``): the wrench found is certified unbalanced, at least a relative
distance ``ρ`` from every balanced wrench. ``ŷ`` is then improved once with the classifier's own
dual direction for the wrench found (the previous optimum stays feasible, so ``τ`` cannot drop).

The wrench found is classified twice: with every contact of the set (it must not be ``held`` or
``jammed``) and with the kept contacts only (the verdict of the motion itself: ``slides`` when
every kept contact slides, ``pivots`` or ``rolls`` when some or all stick; its acceleration must
reach the requested one along ``â`` and open every opening contact). When every contact opens
the push is ``M â − w_g`` (no contact force), checked against the limits; there is no kept
contact, so there is no normal-force margin (``margin_N`` is ``None``).

Without manipulator limits in the file the search bounds the wrench by ``F_max = 5 m |g|``
(``5 m·9.81`` in zero gravity) and ``T_max = F_max ×`` the part's bounding radius, and says so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fixplan.errors import InputError
from fixplan.jamming.backends import ClarabelProgram
from fixplan.jamming.classify import Classification, Classifier
from fixplan.jamming.hand_set import TorqueBox, worst_joint
from fixplan.jamming.programs import ConeProgram, force_layout, wrench_search_program
from fixplan.kinematics import ContactSet
from fixplan.locating import contact_set
from fixplan.settings import DEFAULT, SearchSettings, Settings, Tolerances
from fixplan.spatial import shift_twist

if TYPE_CHECKING:
    from fixplan.model import Fixture
    from fixplan.spatial import Pose

FloatArray = NDArray[np.float64]

_MOVING = ("slides", "pivots", "rolls")


def floor_sig(x: float, digits: int = 4) -> str:
    """``x`` rounded *down* to ``digits`` significant digits, for "≥ x" statements.

    A relative slack of 1e-7 (well below the cone solver's accuracy) keeps ``0.99999999``
    from printing as ``0.9999``; a value is never printed above what was achieved by more
    than that.
    """
    if not math.isfinite(x):
        return str(x)
    if x == 0.0:
        return "0"
    nudge = DEFAULT.numerics.format_nudge_rel
    v = x * (1 + nudge) if x > 0 else x * (1 - nudge)
    e = math.floor(math.log10(abs(v))) - digits + 1
    q = math.floor(v / 10.0**e) * 10.0**e
    return f"{q:.{digits}g}"


def _short_of(value: float, target: float) -> str:
    """``value`` (below ``target``) to 4 significant digits, with more if rounding would reach ``target``."""
    text = f"{value:.4g}"
    digits = 4
    while float(text) >= target and digits < 12:
        text = floor_sig(value, digits)
        digits += 1
    return text


def _finite_or_none(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


@dataclass(frozen=True)
class WrenchSearch:
    """The result of :func:`search_wrench`.

    ``found`` means a push exists that produces the motion without jamming; a margin target
    that is not met leaves ``found`` true but sets ``margin_target_met`` to ``False`` (and says
    so in ``reason``).
    """

    found: bool
    wrench: FloatArray | None  # applied, about the body origin (or ``at``), world axes
    margin_N: float | None  # least normal force over the kept contacts [N]; None: no kept contact
    acceleration: FloatArray | None  # achieved centre-of-mass twist rate (s · â)
    contact_roles: dict[str, str]  # name → "sliding" | "sticking" | "opening"
    contact_forces: dict[str, FloatArray]
    check: Classification | None  # the motion's verdict: the wrench classified on the kept contacts
    reason: str
    binding: list[str] = field(default_factory=list)  # active limits at the optimum
    limits: tuple[float, float] = (float("inf"), float("inf"))
    balance_check: Classification | None = None  # the wrench classified on every contact of the set
    margin_target_N: float | None = None  # the margin asked for (min_margin_N), if any
    margin_target_met: bool | None = None  # None when no target was asked for
    jam_margin_rel: float | None = None  # balance_check's margin / ‖w_e‖_{M⁻¹} (relative distance from balance)
    confirmed: bool = False  # the classifier's motion is the requested one (kind, acceleration ≥ asked)
    # when the hand is too weak: the least force [N] a push needs with its torque within
    # max_torque, and the least torque [N·m] (about the body origin, or ``at``) with its force
    # within max_force; None where no push within that limit moves the part (or not too weak)
    needed_force_N: float | None = None
    needed_torque_Nm: float | None = None
    # headroom: the push is sought within ``limit_fraction`` of the hand's limits first;
    # ``within_fraction`` says whether the one returned is (None: no push returned)
    limit_fraction: float = 1.0
    within_fraction: bool | None = None
    # with an arm's joint-torque boxes (``hand_sets``): the most loaded joint at the push found
    # (``|τ| / τ_max``, its name and where), or at the best push within the hand's limits when
    # the arm is what refuses; None without boxes
    arm_torque_ratio: float | None = None
    arm_joint: str | None = None

    @property
    def force_fraction(self) -> float | None:
        """‖F‖ of the push as a fraction of ``max_force`` (None: no push)."""
        if self.wrench is None or not math.isfinite(self.limits[0]):
            return None
        d = 3 if self.wrench.shape[0] == 6 else 2
        return float(np.linalg.norm(self.wrench[:d])) / self.limits[0]

    @property
    def torque_fraction(self) -> float | None:
        """‖T‖ of the push (about the point it is reported about) as a fraction of ``max_torque``."""
        if self.wrench is None or not math.isfinite(self.limits[1]):
            return None
        d = 3 if self.wrench.shape[0] == 6 else 2
        return float(np.linalg.norm(self.wrench[d:])) / self.limits[1]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dictionary; undefined numbers are ``None`` (never NaN or Infinity)."""
        check, bal = self.check, self.balance_check
        return (
            {
                "found": self.found,
                "wrench": None if self.wrench is None else [float(x) for x in self.wrench],
                "margin": _finite_or_none(self.margin_N),
                "margin_note": None if self.margin_N is not None else "no kept contact: no normal-force margin",
                "margin_target": _finite_or_none(self.margin_target_N),
                "margin_target_met": self.margin_target_met,
                "acceleration": None if self.acceleration is None else [float(x) for x in self.acceleration],
                "contact_roles": dict(self.contact_roles),
                "contact_forces": {k: [float(x) for x in v] for k, v in self.contact_forces.items()},
                "check_mode": None if check is None else check.mode,
                "check_margin": None if check is None else _finite_or_none(check.balance_residual),
                "check_acceleration": None
                if check is None or check.acceleration is None
                else [float(x) for x in check.acceleration],
                "balance_check_mode": None if bal is None else bal.mode,
                "balance_check_margin": None if bal is None else _finite_or_none(bal.balance_residual),
                "jam_margin_rel": _finite_or_none(self.jam_margin_rel),
                "confirmed": self.confirmed,
                "reason": self.reason,
                "binding": list(self.binding),
                "limits": {"max_force": _finite_or_none(self.limits[0]), "max_torque": _finite_or_none(self.limits[1])},
                "needed_force": _finite_or_none(self.needed_force_N),
                "needed_torque": _finite_or_none(self.needed_torque_Nm),
                "limit_fraction": float(self.limit_fraction),
                "within_fraction": self.within_fraction,
                "force_fraction": _finite_or_none(self.force_fraction),
                "torque_fraction": _finite_or_none(self.torque_fraction),
            }
            | self._locators_json()
            | self._arm_json()
        )

    def _arm_json(self) -> dict[str, Any]:
        """``{"arm_torque_ratio": …, "arm_joint": …}`` when the search had an arm's boxes (else nothing)."""
        if self.arm_torque_ratio is None:
            return {}
        return {"arm_torque_ratio": _finite_or_none(self.arm_torque_ratio), "arm_joint": self.arm_joint}

    def _locators_json(self) -> dict[str, Any]:
        """``{"locators": {locator: [contact names]}}`` where a locator has several contacts (else nothing)."""
        for c in (self.balance_check, self.check):
            if c is not None and c.locators:
                return {"locators": {k: list(v) for k, v in c.locators.items()}}
        return {}


def _finite_twist(fixture: Fixture, x: ArrayLike, what: str) -> FloatArray:
    a = np.asarray(x, dtype=float)
    if a.shape != (fixture.ndof,) or not np.all(np.isfinite(a)):
        raise InputError(f"{what} expects {fixture.ndof} finite numbers, got {list(np.atleast_1d(a))}")
    return a


def _tangential_slip(c: Any, u: FloatArray) -> FloatArray:
    """The tangential slip of a contact's relative twist ``u``, torsion scaled to metres (soft fingers)."""
    if c.dimension == 3:
        return np.array([u[1], u[2], c.torsion_m * u[3]]) if c.soft else u[1:3]
    return u[1:2]


def _roles(
    cs: ContactSet, a_hat: FloatArray, ss: SearchSettings, slip: FloatArray | None = None
) -> tuple[dict[str, str], dict[str, FloatArray]]:
    """Each contact's role under the motion ``a_hat`` and, for sliding ones, the unit slip direction.

    Without ``slip`` a kept contact slides when ``a_hat`` makes it slip (a part at rest starting to
    move: friction opposes the acceleration). With ``slip`` (a twist of the centre of mass: the
    velocity the part has, plus what the push adds within a control period) a kept contact whose
    slip under ``slip`` is at least ``ss.slip_rel`` of the twist's speed slides *against that slip*:
    Coulomb friction opposes the velocity, not the acceleration asked for. Opening or closing is
    always judged from ``a_hat`` (within ``ss.role_rel``).
    """
    tol = ss.role_rel
    scale = float(np.linalg.norm(a_hat[: cs.dimension])) + float(np.linalg.norm(a_hat[cs.dimension :])) * cs.max_lever_m
    v_scale = 0.0
    if slip is not None:
        v_scale = (
            float(np.linalg.norm(slip[: cs.dimension])) + float(np.linalg.norm(slip[cs.dimension :])) * cs.max_lever_m
        )
    roles: dict[str, str] = {}
    directions: dict[str, FloatArray] = {}
    for c, off in zip(cs.contacts, cs.offsets, strict=True):
        Ji = cs.J[off : off + c.size]
        u = Ji @ a_hat
        if u[0] < -tol * scale:
            raise InputError(
                f"the motion pushes the workpiece into contact {c.name} (normal rate {u[0]:.3g}); expected a motion that keeps or opens it"
            )
        if u[0] > tol * scale:
            roles[c.name] = "opening"
            continue
        t_v = _tangential_slip(c, Ji @ slip) if slip is not None and v_scale > 0 else None
        t_a = _tangential_slip(c, u)
        if t_v is not None and float(np.linalg.norm(t_v)) > ss.slip_rel * v_scale:
            roles[c.name] = "sliding"
            directions[c.name] = t_v / float(np.linalg.norm(t_v))
        elif float(np.linalg.norm(t_a)) > tol * scale:
            roles[c.name] = "sliding"
            directions[c.name] = t_a / float(np.linalg.norm(t_a))
        else:
            roles[c.name] = "sticking"
    return roles, directions


def _polar_rows(cs: ContactSet) -> tuple[FloatArray, tuple[tuple[str, int], ...]]:
    """``(Q, cones)`` with ``Q y ∈ cones`` ⇔ ``J_i y ∈ K_i*`` at every contact.

    The balanced wrenches are ``{−Jᵀ S f : R f ∈ K}`` (:func:`force_layout`: ``R`` = its
    ``cone_rows``, square and invertible per contact). ``yᵀ(Jᵀ S f) ≥ 0`` for every such ``f``
    ⇔ ``Sᵀ J y ∈ Rᵀ K`` (the cones are self-dual) ⇔ ``Q y = R⁻ᵀ Sᵀ J y ∈ K``.
    """
    lay = force_layout(cs)
    Q = np.asarray(np.linalg.solve(lay.cone_rows.T, lay.S.T @ cs.J), dtype=np.float64)
    return Q, lay.cones


def _certificate(
    cs: ContactSet, target: FloatArray, *, project: bool, shared: dict[str, Any] | None = None, zero_rel: float
) -> FloatArray | None:
    """A unit (``‖ŷ‖_M = 1``) motion ``ŷ`` with ``J_i ŷ ∈ K_i*`` at every contact, or None.

    ``project=True``: the ``M``-projection of the acceleration ``target`` onto that cone.
    ``project=False``: the direction maximising ``ŷᵀ target`` for the wrench ``target`` (the
    dual of the classifier's margin program: its optimum *is* the margin).
    ``shared``: a dictionary kept by the caller across calls on the same ``cs``, which then
    computes ``M``'s Cholesky factor and the polar rows once. A direction shorter than ``zero_rel``
    (``settings.numerics.zero_rel``) of the target's size is none.
    """
    n = cs.ndof
    shared = {} if shared is None else shared
    if "polar" not in shared:
        shared["L"] = np.linalg.cholesky(cs.mass_matrix)
        shared["polar"] = _polar_rows(cs)
    L = shared["L"]
    Q, cones = shared["polar"]
    nx = n + 1
    A_soc = np.zeros((n + 1, nx))
    b_soc = np.zeros(n + 1)
    c = np.zeros(nx)
    if project:  # min t  s.t. ‖Lᵀ(y − â)‖ ≤ t
        A_soc[0, n] = -1.0
        A_soc[1:, :n] = -L.T
        b_soc[1:] = -L.T @ target
        c[n] = 1.0
    else:  # max yᵀ w  s.t. ‖Lᵀ y‖ ≤ 1 (the last variable is unused: fixed at 0)
        A_soc[1:, :n] = -L.T
        b_soc[0] = 1.0
        c[:n] = -target
    A_p = np.zeros((Q.shape[0], nx))
    A_p[:, :n] = -Q
    A_fix = np.zeros((1, nx))
    A_fix[0, n] = 1.0
    parts_A, parts_b, parts_c = [A_soc, A_p], [b_soc, np.zeros(Q.shape[0])], [("soc", n + 1), *cones]
    if not project:
        parts_A.insert(0, A_fix)
        parts_b.insert(0, np.zeros(1))
        parts_c.insert(0, ("zero", 1))
    prog = ConeProgram(c, np.vstack(parts_A), np.concatenate(parts_b), tuple(parts_c), "jam-certificate", 0)
    sol = ClarabelProgram(prog).solve(prog.b)
    if not sol.solved:
        return None
    y = sol.x[:n]
    size = float(np.linalg.norm(L.T @ y))
    ref = float(np.linalg.norm(L.T @ target)) if project else float(np.linalg.norm(np.linalg.solve(L, target)))
    if size <= zero_rel * max(ref, 1e-300) or (not project and float(y @ target) <= 0.0):
        return None
    return y / size


def search_wrench(
    fixture: Fixture,
    motion: ArrayLike,
    contacts: list[str] | None = None,
    *,
    pose: Pose | str | None = None,
    at: ArrayLike | None = None,
    objective: Literal["margin", "effort"] = "margin",
    min_margin_N: float | None = None,
    jam_margin_rel: float | None = None,
    friction_margin: float = 0.0,
    max_accel_factor: float = math.inf,
    slip_twist: ArrayLike | None = None,
    certify: bool = True,
    confirm: bool = True,
    limit_fraction: float | None = None,
    lift_below_weight: bool = True,
    hand_sets: Sequence[TorqueBox] = (),
    settings: Settings = DEFAULT,
) -> WrenchSearch:
    """The applied wrench that moves the part with acceleration ≥ ``motion``, without jamming.

    ``motion`` is the desired acceleration of the body-frame origin (or of ``at``) as a twist
    rate in world axes: ``ax,ay,az,αx,αy,αz`` (2D ``ax,ay,α``) [m/s², rad/s²].

    ``objective="margin"`` (default) returns the wrench with the largest least normal force τ*
    within the limits. ``objective="effort"`` then solves a second program: the least push
    ``‖(F, T_c / L)‖`` (``T_c`` about the centre of mass, ``L`` the largest contact lever) that
    keeps every kept contact pressed by at least ``min(min_margin_N, τ*)`` (default
    ``min_margin_N = m |g|``, the part's weight): a push an operator or a compliant robot can follow
    without the large forces that turn small tracking errors into large disturbances.

    ``min_margin_N`` given explicitly is a *target*: when τ* falls short of it the best push is
    still returned (``found`` true) but ``margin_target_met`` is ``False`` and the reason says
    "margin target … N not met: best … N". Every wrench returned is certified at least
    ``jam_margin_rel`` (relative, in the ``M⁻¹``-norm; default ``settings.search.jam_margin_rel``)
    away from static balance (see the module docstring). When the motion opens every contact the push is ``M â − w_g``.

    ``friction_margin = δ ≥ 0`` makes the push robust to friction known only within a factor
    ``1 ± δ``: the program gives sliding contacts ``μ(1 + δ)`` (the push overcomes the worst
    friction with at least the requested acceleration) and sticking contacts the cone
    ``μ / (1 + δ)`` (they stick even with the least friction). The checks use the nominal μ.
    ``max_accel_factor`` bounds the acceleration along ``motion`` at that many times the
    requested one (a feedback controller asks for *this* acceleration, not at least it).

    ``slip_twist`` (same point and axes as ``motion``, [m/s, rad/s]) is for a part that already
    moves: sliding friction opposes the slip of this twist — pass the velocity the part has plus
    what the push adds within one control period — instead of the slip of ``motion`` (a part at
    rest). A kept contact that slips under it at ≥ ``settings.search.slip_rel`` of its speed slides against that
    slip even where ``motion`` alone would keep it sticking. The jamming certificate is unchanged
    (the wrench would also move the part from rest).

    ``certify=False`` drops the not-jamming constraint: for braking a part that slides
    (``motion`` against its velocity, ``slip_twist`` its velocity) the push that decelerates it as
    asked is one friction would hold at rest, and that is what is wanted. ``found`` then means the
    program solved.

    ``limit_fraction`` (default ``settings.search.limit_fraction``, 0.8) is the headroom kept to
    the hand's limits: every program is first solved with ``‖F‖ ≤ f F_max`` and ``‖T‖ ≤ f T_max``,
    and only when no non-jamming push exists inside them with the whole limits; the reason then
    says so and ``within_fraction`` is false. ``force_fraction`` and ``torque_fraction`` give the
    push found as fractions of the limits. The headroom never costs the kept contacts their hold:
    with ``lift_below_weight`` (default), where the margin inside the fraction stays below the
    weight ``m|g|`` (or ``min_margin_N``), the whole limits are tried too and their push is kept
    when it presses ``settings.search.headroom_margin_gain`` times harder or reaches that margin
    (the reason says so; ``within_fraction`` is false).

    ``confirm=False`` skips the classifier's independent check of the wrench found (its balance
    check and ``check``, both ``None`` then; ``confirmed`` is ``False``): the wrench is still
    certified by the program's own constraint. For a feedback loop that re-solves the push many
    times a second and watches the motion it causes, where the check was a quarter of each solve.

    ``hand_sets``: the arm's joint-torque boxes (:class:`~fixplan.jamming.hand_set.TorqueBox`, one
    per pose the push must be exertable at) in addition to the force and torque limits: every
    push is sought with ``|τ_g + Jᵀ w| ≤ τ_max`` at each (within ``limit_fraction`` of the
    effort limits first, like the hand's limits). When the boxes are what refuses (a push within
    the hand's limits exists, none the arm can exert) the reason names the joint and the pose.
    ``arm_torque_ratio`` and ``arm_joint`` give the most loaded joint at the push found.

    This is the fixture-level form: it builds the contact set at ``pose`` and moves ``motion``
    (and ``slip_twist``) from the body origin (or ``at``) to the centre of mass, then calls
    :func:`search_wrench_in`, which a caller holding a contact set calls directly.

    ``settings`` (default: the ``default`` profile) gives every threshold of the search
    (:class:`fixplan.settings.SearchSettings`, ``settings.search``).
    """
    m = np.asarray(motion, dtype=float)
    if m.shape != (fixture.ndof,) or not np.all(np.isfinite(m)):
        raise InputError(f"search_wrench.motion expects {fixture.ndof} finite numbers, got {list(np.atleast_1d(m))}")
    if float(np.linalg.norm(m)) == 0.0:
        raise InputError("search_wrench.motion is zero (expected the desired acceleration of the part)")
    jam_margin_rel = settings.search.jam_margin_rel if jam_margin_rel is None else jam_margin_rel
    _check_options(objective, min_margin_N, friction_margin, jam_margin_rel)
    cs = contact_set(fixture, pose, contacts)
    _check_contacts(cs)
    about = cs.body_origin_world if at is None else np.asarray(at, dtype=float)
    a_com = shift_twist(m, about, cs.com_world)
    slip_com = (
        None
        if slip_twist is None
        else shift_twist(_finite_twist(fixture, slip_twist, "slip_twist"), about, cs.com_world)
    )
    return search_wrench_in(
        cs,
        a_com,
        fixture,
        about_world=about,
        objective=objective,
        min_margin_N=min_margin_N,
        jam_margin_rel=jam_margin_rel,
        friction_margin=friction_margin,
        max_accel_factor=max_accel_factor,
        slip_com=slip_com,
        certify=certify,
        confirm=confirm,
        limit_fraction=limit_fraction,
        lift_below_weight=lift_below_weight,
        hand_sets=hand_sets,
        settings=settings,
    )


def _check_options(objective: str, min_margin_N: float | None, friction_margin: float, jam_margin_rel: float) -> None:
    if objective not in ("margin", "effort"):
        raise InputError(f"unknown search objective {objective!r} (expected 'margin' or 'effort')")
    if min_margin_N is not None and not (math.isfinite(min_margin_N) and min_margin_N >= 0.0):
        raise InputError(f"min_margin_N must be a non-negative number of newtons, got {min_margin_N}")
    if not (math.isfinite(friction_margin) and friction_margin >= 0.0):
        raise InputError(f"friction_margin must be a finite number ≥ 0, got {friction_margin}")
    if not (0.0 < jam_margin_rel < 1.0):
        raise InputError(f"jam_margin_rel must lie in (0, 1), got {jam_margin_rel}")


def _check_contacts(cs: ContactSet) -> None:
    if len(cs) == 0:
        raise InputError("no contacts to analyse (the workpiece touches no locator here; name contacts explicitly)")


def search_wrench_in(
    cs: ContactSet,
    a_com: ArrayLike,
    fixture: Fixture,
    *,
    about_world: ArrayLike | None = None,
    objective: str = "margin",
    min_margin_N: float | None = None,
    jam_margin_rel: float | None = None,
    friction_margin: float = 0.0,
    max_accel_factor: float = math.inf,
    slip_com: ArrayLike | None = None,
    certify: bool = True,
    confirm: bool = True,
    limit_fraction: float | None = None,
    lift_below_weight: bool = True,
    hand_sets: Sequence[TorqueBox] = (),
    settings: Settings = DEFAULT,
) -> WrenchSearch:
    """:func:`search_wrench` for a contact set already built, with the motion of the centre of mass.

    ``a_com`` is the desired acceleration of the centre of mass ``cs.com_world`` (and
    ``slip_com`` the slip twist, see :func:`search_wrench`), world axes: no shift to and from
    the body origin. ``fixture`` gives gravity, the hand's limits and the tolerances; the wrench
    found is reported about ``about_world`` (default: the body origin ``cs.body_origin_world``).
    The other arguments (``settings`` among them) and the answer are those of :func:`search_wrench`.
    """
    ss = settings.search
    jam_margin_rel = ss.jam_margin_rel if jam_margin_rel is None else jam_margin_rel
    a_hat = np.asarray(a_com, dtype=float)
    if a_hat.shape != (cs.ndof,) or not np.all(np.isfinite(a_hat)):
        raise InputError(f"search_wrench_in.a_com expects {cs.ndof} finite numbers, got {list(np.atleast_1d(a_hat))}")
    if float(np.linalg.norm(a_hat)) == 0.0:
        raise InputError("search_wrench_in.a_com is zero (expected the desired acceleration of the part)")
    _check_options(objective, min_margin_N, friction_margin, jam_margin_rel)
    _check_contacts(cs)
    about = cs.body_origin_world if about_world is None else np.asarray(about_world, dtype=float)
    slip = None if slip_com is None else np.asarray(slip_com, dtype=float)
    if slip is not None and (slip.shape != (cs.ndof,) or not np.all(np.isfinite(slip))):
        raise InputError(f"slip_twist expects {cs.ndof} finite numbers, got {list(np.atleast_1d(slip))}")
    frac = ss.limit_fraction if limit_fraction is None else float(limit_fraction)
    if not (0.0 < frac <= 1.0):
        raise InputError(f"limit_fraction must lie in (0, 1], got {limit_fraction}")
    roles, directions = _roles(cs, a_hat, ss, slip)
    F_max, T_max, notes = fixture.hand_limits()
    w_g = fixture.gravity_wrench()
    target = None if min_margin_N is None else float(min_margin_N)
    kept = [i for i, c in enumerate(cs.contacts) if roles[c.name] != "opening"]
    boxes = tuple(hand_sets)
    if boxes and cs.dimension != 3:
        raise InputError("an arm's joint-torque boxes (hand_sets) are for 3D scenes (expected none in 2D)")
    if not kept:
        return _free_push(
            cs, a_hat, roles, about, w_g, (F_max, T_max), notes, target,
            boxes=boxes, tolerances=fixture.tolerances, settings=settings, frac=frac,
        )  # fmt: skip

    def not_found(
        reason: str, binding: list[str] | None = None, needs: tuple[float | None, float | None] = (None, None)
    ) -> WrenchSearch:
        return WrenchSearch(
            False, None, None, None, roles, {}, None, reason, binding or [], (F_max, T_max), margin_target_N=target,
            needed_force_N=needs[0], needed_torque_Nm=needs[1], limit_fraction=frac,
        )  # fmt: skip

    polar: dict[str, Any] = {}  # the certificates' factors of cs, computed once
    y = _certificate(cs, a_hat, project=True, shared=polar, zero_rel=settings.numerics.zero_rel) if certify else None
    if certify and (y is None or float(y @ cs.mass_matrix @ a_hat) <= 0.0):
        return not_found(
            "every push that produces this motion can also be balanced by the contact forces (M a is a contact"
            " reaction): it jams"
        )
    cs_design = _robust_friction(cs, roles, friction_margin) if friction_margin > 0 else cs
    if not max_accel_factor >= 1.0:
        raise InputError(f"max_accel_factor must be ≥ 1, got {max_accel_factor}")
    build = dict(
        cs=cs_design,
        a_hat=a_hat,
        roles=roles,
        directions=directions,
        w_g=w_g,
        about=about,
        jam=jam_margin_rel,
        s_max=max_accel_factor,
        shared={},  # the builds' common parts (one contact set, one set of roles)
        hand_sets=boxes,
    )
    # headroom: first within the fraction of the limits, the whole limits only when nothing moves
    # the part inside it (one more program then)
    F_lim, T_lim, h_lim = frac * F_max, frac * T_max, frac
    prog, meta = wrench_search_program(**build, cert=y, F_max=F_lim, T_max=T_lim, hand_frac=h_lim)  # type: ignore[arg-type]
    sol = ClarabelProgram(prog).solve(prog.b)
    within = bool(sol.solved and -sol.value > ss.found_rel * F_max)
    # the headroom must not cost the contacts their hold: where the margin inside the fraction
    # stays below the weight m|g| (or the target asked for), the whole limits are tried too and
    # kept when they press the kept contacts clearly harder
    weight_N = fixture.weight_N if target is None else target
    tau_within = float(-sol.value) if within else 0.0
    lifted = False
    if lift_below_weight and within and frac < 1.0 and tau_within < weight_N * (1 - ss.target_rel):
        prog_f, meta_f = wrench_search_program(**build, cert=y, F_max=F_max, T_max=T_max)  # type: ignore[arg-type]
        sol_f = ClarabelProgram(prog_f).solve(prog_f.b)
        if sol_f.solved and -sol_f.value > min(tau_within * ss.headroom_margin_gain, weight_N):
            prog, meta, sol, F_lim, T_lim, h_lim, lifted = prog_f, meta_f, sol_f, F_max, T_max, 1.0, True
    if not within and frac < 1.0:
        F_lim, T_lim, h_lim = F_max, T_max, 1.0
        prog, meta = wrench_search_program(**build, cert=y, F_max=F_lim, T_max=T_lim)  # type: ignore[arg-type]
        sol = ClarabelProgram(prog).solve(prog.b)
    n = cs.ndof
    if not sol.solved or -sol.value <= ss.found_rel * F_max:
        # Diagnose: is it the arm, the hand's limits, or the motion itself?
        if boxes:
            arm_said = _arm_refuses(build, y, F_max, T_max, boxes, about, ss)
            if arm_said is not None:
                return replace(not_found(arm_said[0], ["arm"]), arm_torque_ratio=arm_said[1], arm_joint=arm_said[2])
        big = ss.unbounded_factor
        prog_free, _ = wrench_search_program(**build, cert=y, F_max=big * F_max, T_max=big * T_max, hand_frac=None)  # type: ignore[arg-type]
        free = ClarabelProgram(prog_free).solve(prog_free.b)
        if free.solved and -free.value > ss.found_rel * F_max:
            reason, binding, needs = _too_weak(build, y, F_max, T_max, ss)
            return not_found(reason + notes, binding, needs)
        return not_found(
            "no wrench moves the part this way while keeping the contacts pressed and clear of jamming"
            " (every such push jams or opens a contact)"
        )
    x, tau = sol.x, float(-sol.value)
    # a better certificate: the classifier's own dual direction for the wrench found (the
    # optimum above stays feasible with it, so τ cannot drop)
    y2 = (
        _certificate(cs, x[:n] + w_g, project=False, shared=polar, zero_rel=settings.numerics.zero_rel)
        if certify
        else None
    )
    if y2 is not None:
        prog2, meta2 = wrench_search_program(**build, cert=y2, F_max=F_lim, T_max=T_lim, hand_frac=h_lim)  # type: ignore[arg-type]
        sol2 = ClarabelProgram(prog2).solve(prog2.b)
        if sol2.solved and -sol2.value >= tau:
            x, tau, meta, y = sol2.x, float(-sol2.value), meta2, y2
    tau_best = tau
    if objective == "effort":
        wanted = fixture.weight_N if target is None else target
        tau_req = wanted if wanted < tau * (1 - ss.target_rel) else tau * (1 - ss.target_rel)
        prog_e, meta_e = wrench_search_program(
            **build,  # type: ignore[arg-type]
            cert=y, F_max=F_lim, T_max=T_lim, effort_margin_N=tau_req, hand_frac=h_lim,
        )  # fmt: skip
        sol_e = ClarabelProgram(prog_e).solve(prog_e.b)
        if sol_e.solved:
            x, meta = sol_e.x, meta_e
            tau = float(x[meta["tau"]])
        else:
            notes += " (the least-effort program did not solve: the best-margin push is returned)"
        if target is None and wanted > tau_best * (1 + ss.target_rel):
            within_text = f" within {frac:.0%} of the hand's limits" if within and frac < 1.0 else ""
            notes += (
                f" (default margin m|g| = {wanted:.4g} N not reachable{within_text}: best {floor_sig(tau_best)} N used;"
                " a smaller search_wrench.min_margin_N asks for a lighter push)"
            )
    w_com = x[:n]
    s = float(x[meta["s"]])
    lam = meta["expand"](x)
    forces = {c.name: lam[o : o + c.size] for c, o in zip(cs.contacts, cs.offsets, strict=True)}
    w_user = cs.wrench_about(w_com, about)  # the applied wrench about the user's point
    binding = []
    if abs(float(np.linalg.norm(w_com[: cs.dimension])) - F_max) <= ss.binding_rel * F_max:
        binding.append("max_force")
    if abs(float(np.linalg.norm(w_user[cs.dimension :])) - T_max) <= ss.binding_rel * T_max:
        binding.append("max_torque")
    arm_ratio, arm_joint, _ = worst_joint(boxes, w_user, about) if boxes else (None, None, "")
    if arm_ratio is not None and arm_ratio >= 1.0 - ss.binding_rel:
        binding.append(f"joint {arm_joint}")
    if not within and frac < 1.0:
        notes += _beyond_fraction(w_user, cs.dimension, F_max, T_max, frac)
    elif lifted:
        notes += _lifted_fraction(w_user, cs.dimension, F_max, T_max, frac, tau_within)
        within = False

    met = None if target is None else bool(tau_best >= target * (1 - ss.target_rel))
    if not confirm:
        reason = ("decelerates the sliding part as asked" if not certify else "moves as asked") + (
            f" with every kept contact pressed by ≥ {floor_sig(tau)} N (not checked by the classifier){notes}"
        )
        if met is False and target is not None:
            reason = f"margin target {target:.4g} N not met: best {_short_of(tau_best, target)} N; " + reason
        return WrenchSearch(
            True, w_user, tau, s * a_hat, roles, forces, None, reason, binding, (F_max, T_max),
            margin_target_N=target, margin_target_met=met, limit_fraction=frac, within_fraction=within,
            arm_torque_ratio=arm_ratio, arm_joint=arm_joint,
        )  # fmt: skip
    clf_all = Classifier(cs, w_g, tolerances=fixture.tolerances, witness=settings.witness)
    bal = clf_all.classify(w_com, w_user)
    w_e_norm = clf_all.builder.m_inv_norm(w_com + w_g)
    jam_rel = bal.balance_residual / w_e_norm if w_e_norm > 0 and math.isfinite(bal.balance_residual) else None
    if len(kept) == len(cs):
        check = bal
    else:
        kept_cs = ContactSet(tuple(cs.contacts[i] for i in kept), cs.com_world, cs.mass_matrix, cs.body_origin_world)
        check = Classifier(kept_cs, w_g, tolerances=fixture.tolerances, witness=settings.witness).classify(
            w_com, w_user
        )
    confirmed, why_not = _confirm(cs, check, a_hat, roles, ss)
    if bal.balanced and certify:
        reason = f"the wrench found is statically balanced ({bal.mode}): it would not move the part"
    elif not certify:
        reason = f"decelerates the sliding part as asked with every kept contact pressed by ≥ {floor_sig(tau)} N{notes}"
    else:
        reason = f"moves as asked with every kept contact pressed by ≥ {floor_sig(tau)} N{notes}"
        if met is False and tau_best is not None and target is not None:
            reason = f"margin target {target:.4g} N not met: best {_short_of(tau_best, target)} N; " + reason
        if not confirmed:
            reason += f" (not confirmed by the classifier: {why_not})"
    return WrenchSearch(
        (not bal.balanced) or not certify,
        w_user,
        tau,
        s * a_hat,
        roles,
        forces,
        check,
        reason,
        binding,
        (F_max, T_max),
        balance_check=bal,
        margin_target_N=target,
        margin_target_met=met,
        jam_margin_rel=jam_rel,
        confirmed=confirmed and not bal.balanced,
        limit_fraction=frac,
        within_fraction=within,
        arm_torque_ratio=arm_ratio,
        arm_joint=arm_joint,
    )


def _arm_refuses(
    build: dict[str, Any],
    cert: FloatArray | None,
    F_max: float,
    T_max: float,
    boxes: tuple[TorqueBox, ...],
    about: FloatArray,
    ss: SearchSettings,
) -> tuple[str, float, str] | None:
    """``(reason, ratio, joint)`` when a push within the hand's limits exists but the arm cannot exert it, else None.

    The best-margin push without the arm's boxes is found and its most loaded joint named:
    ``|τ| / τ_max`` there, and the pose (the box's label).
    """
    cs: ContactSet = build["cs"]
    prog, _ = wrench_search_program(**build, cert=cert, F_max=F_max, T_max=T_max, hand_frac=None)
    sol = ClarabelProgram(prog).solve(prog.b)
    if not sol.solved or -sol.value <= ss.found_rel * F_max:
        return None
    w_user = cs.wrench_about(sol.x[: cs.ndof], about)
    ratio, joint, label = worst_joint(boxes, w_user, about)
    where = f" at {label}" if label else ""
    reason = (
        f"the arm cannot exert the push: no non-jamming push within the hand's limits keeps every joint within its"
        f" effort limit; the best-margin one needs joint {joint} at {ratio:.3g} times its effort limit{where}"
    )
    return reason, ratio, joint


def _with_arm(res: WrenchSearch, boxes: tuple[TorqueBox, ...], about: FloatArray, ss: SearchSettings) -> WrenchSearch:
    """A free push (every contact opens, the push determined) checked against the arm's boxes too."""
    if not boxes or res.wrench is None:
        return res
    ratio, joint, label = worst_joint(boxes, res.wrench, about)
    if ratio <= 1.0 + ss.limit_rel:
        return replace(res, arm_torque_ratio=ratio, arm_joint=joint)
    where = f" at {label}" if label else ""
    reason = f"the arm cannot exert the push M a − w_g: joint {joint} needs {ratio:.3g} times its effort limit{where}"
    return replace(
        res, found=False, wrench=None, reason=reason, binding=["arm"], arm_torque_ratio=ratio, arm_joint=joint,
        confirmed=False, within_fraction=None,
    )  # fmt: skip


def _beyond_fraction(w_user: FloatArray, d: int, F_max: float, T_max: float, frac: float) -> str:
    """The note of a push that needs more than ``frac`` of the hand's limits (none inside exists)."""
    f = float(np.linalg.norm(w_user[:d])) / F_max
    t = float(np.linalg.norm(w_user[d:])) / T_max
    return (
        f" (no non-jamming push within {frac:.0%} of the hand's limits: this one uses {f:.0%} of max_force"
        f" and {t:.0%} of max_torque)"
    )


def _lifted_fraction(w_user: FloatArray, d: int, F_max: float, T_max: float, frac: float, tau_within: float) -> str:
    """The note of a push beyond ``frac`` of the limits because inside it the margin stays below the weight."""
    f = float(np.linalg.norm(w_user[:d])) / F_max
    t = float(np.linalg.norm(w_user[d:])) / T_max
    return (
        f" (within {frac:.0%} of the hand's limits the kept contacts are pressed by only {floor_sig(tau_within)} N,"
        f" less than the weight: this push uses {f:.0%} of max_force and {t:.0%} of max_torque)"
    )


def _confirm(
    cs: ContactSet, check: Classification, a_hat: FloatArray, roles: dict[str, str], ss: SearchSettings
) -> tuple[bool, str]:
    """Check the classifier's motion against the request: kind, acceleration ≥ â along â, openings."""
    kept_roles = [r for r in roles.values() if r != "opening"]
    if all(r == "sliding" for r in kept_roles):
        expected = "slides"
    elif all(r == "sticking" for r in kept_roles):
        expected = "rolls"
    else:
        expected = "pivots"
    if check.mode not in _MOVING or check.acceleration is None:
        return False, f"it says {check.mode} where {expected} was expected"
    a = np.asarray(check.acceleration, dtype=float)
    M = cs.mass_matrix
    ref = float(a_hat @ M @ a_hat)
    along = float(a @ M @ a_hat) / ref
    off_axis = a - along * a_hat
    if along < 1 - ss.along_rel:
        return False, f"its acceleration is {along:.4g} × the requested one"
    if float(off_axis @ M @ off_axis) > ss.off_axis_rel**2 * float(a @ M @ a):
        return False, "its acceleration points elsewhere than the requested motion"
    for c, off in zip(cs.contacts, cs.offsets, strict=True):
        if roles[c.name] == "opening" and float(cs.J[off] @ a) <= 0.0:
            return False, f"{c.name} does not open under its motion"
    return True, ""


def _above(value: float, limit: float) -> str:
    """``value`` (above ``limit``) to 4 significant digits, with more if rounding would reach ``limit``."""
    digits = 4
    text = f"{value:.{digits}g}"
    while float(text) <= limit and digits < 12:
        digits += 1
        text = f"{value:.{digits}g}"
    return text


def too_weak_reason(
    F_need: float | None,
    F_with: float | None,
    T_need: float | None,
    T_with: float | None,
    F_max: float,
    T_max: float,
    settings: SearchSettings = DEFAULT.search,
) -> tuple[str, list[str]]:
    """The "too weak" message and the binding limits, from the least force and the least torque.

    ``F_need`` is the least force [N] a push needs with its torque within ``T_max`` (``T_with`` its
    torque there), ``T_need`` the least torque [N·m] with the force within ``F_max`` (``F_with`` its
    force); None: no push within that limit. A limit binds alone when the least push beyond it keeps
    the other limit slack (below ``1 − settings.binding_rel`` of it); otherwise both bind.
    """
    slack = 1 - settings.binding_rel
    torque_alone = T_need is not None and T_need > T_max and F_with is not None and F_with < slack * F_max
    force_alone = F_need is not None and F_need > F_max and T_with is not None and T_with < slack * T_max
    head = "the manipulator is too weak: "
    if torque_alone and not force_alone and T_need is not None and F_with is not None:
        return (
            head + f"the push needs {_above(T_need, T_max)} N·m of torque, more than max_torque {T_max:.4g} N·m"
            f" (its force, {F_with:.4g} N, is within max_force {F_max:.4g} N)",
            ["max_torque"],
        )
    if force_alone and not torque_alone and F_need is not None and T_with is not None:
        return (
            head + f"the push needs {_above(F_need, F_max)} N of force, more than max_force {F_max:.4g} N"
            f" (its torque, {T_with:.4g} N·m, is within max_torque {T_max:.4g} N·m)",
            ["max_force"],
        )
    torque = (
        f"no push within max_force {F_max:.4g} N moves the part this way"
        if T_need is None
        else f"within max_force {F_max:.4g} N it needs {_above(T_need, T_max)} N·m of torque (max_torque {T_max:.4g} N·m)"
    )
    force = (
        f"no push within max_torque {T_max:.4g} N·m moves it this way"
        if F_need is None
        else f"within max_torque {T_max:.4g} N·m it needs {_above(F_need, F_max)} N of force (max_force {F_max:.4g} N)"
    )
    return head + f"no push meets both limits at once: {torque}; {force}", ["max_force", "max_torque"]


def _too_weak(
    build: dict[str, Any], cert: FloatArray | None, F_max: float, T_max: float, ss: SearchSettings
) -> tuple[str, list[str], tuple[float | None, float | None]]:
    """Why no push within the limits exists: the least force and the least torque it needs.

    Two cone programs with the search's own constraints (the motion, the contact roles and cones,
    not jamming, every kept contact pressed by the least margin that counts as found): the least
    ``‖F‖`` with ``‖T‖ ≤ T_max``, and the least ``‖T‖`` (about the user's point) with
    ``‖F‖ ≤ F_max``. Returns the message, the binding limits and ``(F_need, T_need)``.
    """
    cs: ContactSet = build["cs"]
    d = cs.dimension
    tau_min = ss.found_rel * F_max
    big = ss.unbounded_factor

    def least(kind: Literal["force", "torque"], F_lim: float, T_lim: float) -> tuple[float, float] | None:
        prog, _ = wrench_search_program(
            **build, cert=cert, F_max=F_lim, T_max=T_lim, effort_margin_N=tau_min, least=kind, hand_frac=None
        )
        sol = ClarabelProgram(prog).solve(prog.b)
        if not sol.solved:
            return None
        w_com = sol.x[: cs.ndof]
        w_user = cs.wrench_about(w_com, build["about"])
        return float(np.linalg.norm(w_com[:d])), float(np.linalg.norm(w_user[d:]))

    by_force = least("force", big * F_max, T_max)
    by_torque = least("torque", F_max, big * T_max)
    F_need, T_with = by_force if by_force is not None else (None, None)
    F_with, T_need = by_torque if by_torque is not None else (None, None)
    reason, binding = too_weak_reason(F_need, F_with, T_need, T_with, F_max, T_max, ss)
    return reason, binding, (F_need, T_need)


def _free_push(
    cs: ContactSet,
    a_hat: FloatArray,
    roles: dict[str, str],
    about: FloatArray,
    w_g: FloatArray,
    limits: tuple[float, float],
    notes: str,
    target: float | None,
    *,
    boxes: tuple[TorqueBox, ...],
    tolerances: Tolerances,
    settings: Settings,
    frac: float = 1.0,
) -> WrenchSearch:
    """Every contact opens: no contact force, the push is ``w = M â − w_g`` (checked, not optimised).

    Checked against the hand's ``limits``, then by the classifier on the contacts (it must not be
    balanced), then against the arm's ``boxes`` (:func:`_with_arm`).
    """
    ss = settings.search
    F_max, T_max = limits
    d = cs.dimension
    clf = Classifier(cs, w_g, tolerances=tolerances, witness=settings.witness)  # the contacts, with gravity
    w_com = cs.mass_matrix @ a_hat - w_g
    w_user = cs.wrench_about(w_com, about)
    F = float(np.linalg.norm(w_com[:d]))
    T = float(np.linalg.norm(w_user[d:]))
    forces = {c.name: np.zeros(c.size) for c in cs.contacts}
    met = None if target is None else True  # no kept contact: the least normal force is vacuous
    if F > F_max * (1 + ss.limit_rel) or T > T_max * (1 + ss.limit_rel):
        # the push is determined: its force and torque are the least needed
        reason, binding = too_weak_reason(F, F, T, T, F_max, T_max, ss)
        reason += f" (every contact opens: the push is M a − w_g){notes}"
        return WrenchSearch(
            False, None, None, None, roles, {}, None, reason, binding, limits, margin_target_N=target,
            needed_force_N=F, needed_torque_Nm=T, limit_fraction=frac,
        )  # fmt: skip
    bal = clf.classify(w_com, w_user)
    w_e_norm = clf.builder.m_inv_norm(w_com + w_g)
    jam_rel = bal.balance_residual / w_e_norm if w_e_norm > 0 and math.isfinite(bal.balance_residual) else None
    # the push is determined: inside the headroom or not, it is the only one
    within = F <= frac * F_max * (1 + ss.limit_rel) and T <= frac * T_max * (1 + ss.limit_rel)
    if not within:
        notes += _beyond_fraction(w_user, d, F_max, T_max, frac)
    if bal.balanced:
        reason = f"every contact opens, but M a − w_g is statically balanced ({bal.mode}): it would not move the part"
    else:
        reason = f"every contact opens: free motion, the push is M a − w_g, ‖F‖ = {F:.4g} N, ‖T‖ = {T:.4g} N·m{notes}"
    res = WrenchSearch(
        not bal.balanced,
        w_user,
        None,
        a_hat.copy(),
        roles,
        forces,
        bal,
        reason,
        [],
        limits,
        balance_check=bal,
        margin_target_N=target,
        margin_target_met=met,
        jam_margin_rel=jam_rel,
        confirmed=not bal.balanced,
        limit_fraction=frac,
        within_fraction=within,
    )
    return _with_arm(res, boxes, about, ss)


def _robust_friction(cs: ContactSet, roles: dict[str, str], delta: float) -> ContactSet:
    """The contact set with friction ``μ(1 + δ)`` on sliding contacts and ``μ / (1 + δ)`` on the others."""
    contacts = tuple(
        replace(c, friction=c.friction * ((1.0 + delta) if roles[c.name] == "sliding" else 1.0 / (1.0 + delta)))
        for c in cs.contacts
    )
    return ContactSet(contacts, cs.com_world, cs.mass_matrix, cs.body_origin_world)
