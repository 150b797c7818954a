"""Exact one-contact solvers: the contact law for ``u = W_jj P + α̂`` at a single contact.

Every nonsmooth Gauss–Seidel sweep (:mod:`fixplan.engine.nsgs`) calls one of these per contact.
They solve the one-contact problem *exactly* (to rounding), never on a linearized cone.

Problem
-------
Given a ``d × d`` matrix ``W`` (the diagonal Delassus block ``W_jj``, symmetric positive
definite in the usual case; a non-symmetric ``W`` with positive definite symmetric part is
also handled), a vector ``α̂`` (the free velocity of the contact, ``α̂ = q_j + Σ_{k≠j} W_jk P_k``)
and a friction coefficient ``μ ≥ 0``, find the impulse ``P = (P_n, P_t)`` and the velocity
``u = W P + α̂`` with (docs/math.md, "Contact laws")::

    K_μ ∋ P ⊥ ũ ∈ K_μ*,   ũ = u + (μ ‖u_t‖, 0, …),   K_μ = {‖P_t‖ ≤ μ P_n}.

Component order is always ``(normal, tangent1[, tangent2[, spin]])``, as in FCLib.
``d = 1 + k`` with ``k = 1`` (2D Coulomb), ``k = 2`` (3D Coulomb), ``k = 3`` (soft finger after
scaling, below).

Method (all ``k``)
------------------
The law has three regimes, tried in this order:

1. **open** – ``α̂_n ≥ 0``: ``P = 0`` (then ``ũ_n − μ‖ũ_t‖ = α̂_n ≥ 0``, so ``ũ ∈ K_μ*``).
2. **stick** – ``u = 0``: ``P = −W⁻¹ α̂``, accepted when it lies in ``K_μ``.
3. **slide** – ``u_n = 0``, ``u_t = −γ P_t`` for some ``γ > 0`` (friction opposes sliding,
   ``‖P_t‖ = μ P_n``). For a fixed ``γ`` the two conditions are the linear system
   ``(W + γ E_t) P(γ) = −α̂`` with ``E_t = diag(0, I_k)``, so the whole sliding case is the
   scalar equation::

       φ(γ) = ‖P_t(γ)‖ − μ P_n(γ) = 0,   γ ∈ (0, ∞).

   If stick failed, ``φ(0⁺) > 0``; as ``γ → ∞``, ``P_t → 0`` and ``P_n → −α̂_n / W_nn > 0`` so
   ``φ(∞) < 0``; ``W + γE_t`` is nonsingular for ``γ > 0`` whenever ``W`` is positive
   semidefinite with ``W_nn > 0``. A root therefore exists and is bracketed. Any root has
   ``P_n = ‖P_t‖/μ ≥ 0``. This is the "hybrid" exact approach: closed-form regimes plus a
   one-dimensional root find; no cone is ever linearized.

Numerical details (each one fixed a failure found by the tests or by hypothesis):

- the data are normalized first (``W / max|W|``, ``α̂ / max|α̂|``; the law is homogeneous), and
  norms are computed without under/overflow, so ``|α̂_n| ≪ ‖α̂_t‖`` (1e-196 against 1) works;
- ``W + γE_t`` is factored with diagonal pivots (no row exchange: partial pivoting mixed the
  ``γ``-sized tangential rows into the normal one for ``γ ≫ ‖W‖`` and lost ``P_n``);
- the first ``γ`` is the root for an isotropic block, and the root is polished by safeguarded
  Newton on ``ψ(γ) = 1/‖P_t‖ − 1/(μ P_n)`` (affine in ``γ`` for ``W = wI``; same root as ``φ``),
  with geometric bisection as the safeguard — 3–5 factorizations of a ``d × d`` matrix per
  sliding contact on random blocks (about 2 µs per 3D solve on the reference machine);
- for an ill-conditioned block (cond up to 1e12 tested) ``φ`` carries a rounding error
  ``~cond·ε``; it is cancelled along the direction that moves ``u`` least (``(WᵀW)⁻¹∇φ``), then
  ``P_t`` is rescaled onto the cone surface, so membership holds exactly and ``u`` stays
  accurate (law violation ≤ 4e-16 measured at cond 1e12);
- a root is accepted only if ``u_n ≈ 0`` and ``u_t`` opposes ``P_t`` (backward check, relative
  1e-9); otherwise the closed form for the root's sliding direction ``ŝ`` is tried,
  ``P_n = −α̂_n / (W_nn − μ W_nt·ŝ)``, and when the root lies beyond ``γ = 1e16‖W‖`` the
  direction is ``ŝ = α̂_t/‖α̂_t‖`` (``‖WP‖ ≪ ‖α̂‖``: exact to rounding);
- ``μ < 1e-17`` is frictionless (the friction it allows is below rounding).

For ``k = 1`` the sliding case is in closed form (the sliding direction is ``±1``):
``P_n = −α̂_n / (W_nn ∓ μ W_nt)``; :func:`solve_coulomb_2d` enumerates the four regimes and only
falls back on the root find when rounding rejects all of them.

Soft finger (docs/math.md [10])
--------------------------
``P_t1² + P_t2² + P_s²/e_r² ≤ μ² P_n²`` (``e_x = e_y = 1``, ``e_r`` the torsion radius [m]).
With ``s = (1, 1, 1, e_r)`` the scaled impulse ``P̃ = P / s`` and scaled velocity ``ũ = s ∘ u``
satisfy the standard law in a 4-dimensional second-order cone, with ``W̃ = diag(s) W diag(s)``
and ``α̃ = s ∘ α̂`` (the power ``P·u = P̃·ũ`` is unchanged). :func:`solve_soft_finger` solves the
scaled problem with :func:`solve_cone` and maps back: ``P = s ∘ P̃``.

Regime codes
------------
What the one-contact solvers return is the contact's *regime*, not how a solve ended (that is
the engine's one status vocabulary, :mod:`fixplan.engine.status`, whose 1 and 2 mean other
things): ``OPEN = 0``, ``STICK = 1``, ``SLIDE = 2``; ``FAILED = -1`` when no regime could be established
(e.g. ``W_nn = 0`` with ``α̂_n < 0``: the contact cannot stop its own approach; or a singular
PSD ``W`` for which no finite solution exists); ``P`` is then the candidate of least
natural-map residual among ``0`` and the normal-only impulse, always finite.

Every function here is compiled with ``numba.njit(cache=True, error_model="numpy")``; the
``*_into`` variants write into a caller's array, the ``*_ws`` variants also take a scratch
array of ``WORKSPACE_SIZE`` floats (no allocation inside a compiled sweep). Arguments must be
float64 arrays. Note for developers: numba's cache does not track dependencies, so a compiled
caller in another module keeps a stale copy of these functions after they change; delete
``fixplan/engine/__pycache__/*.nb[ic]`` then.
"""

from __future__ import annotations

import math

import numba
import numpy as np

OPEN = 0
STICK = 1
SLIDE = 2
FAILED = -1

REGIME_NAMES = {OPEN: "open", STICK: "stick", SLIDE: "slide", FAILED: "failed"}
"""The words of the regime codes."""

_EPS = 2.220446049250313e-16
_PIVOT_REL = 1e-13  # a pivot below this fraction of its column's max counts as zero
_MAX_ROOT_ITER = 200
_MU_ZERO = 1e-17  # μ below this is frictionless: the friction it allows is below rounding
WORKSPACE_SIZE = 72
"""Floats of scratch space one solve needs (``*_ws`` variants); layout: LU 0:16, column
scales 16:20, root-find vectors 20:40, normalized block 40:60, fallback vectors 60:72."""


# --------------------------------------------------------------------------- small dense LU


@numba.njit(cache=True, error_model="numpy")
def _lu_factor(A, gamma, LU, colscale):
    """LU of ``A + γ E_t`` with diagonal pivots (``d ≤ 4``); ``False`` if singular.

    No row exchanges: ``W_jj`` has a positive definite (or semidefinite) symmetric part, for
    which diagonal pivoting is backward stable (it is Cholesky up to scaling), and it keeps the
    normal row apart from the ``γ``-sized tangential rows — partial pivoting swapped them for
    ``γ ≫ ‖W‖`` and lost ``P_n`` to cancellation. A pivot counts as zero when it is below
    ``_PIVOT_REL`` times the largest entry of its column (``colscale``: workspace, length d).
    """
    d = A.shape[0]
    for j in range(d):
        colscale[j] = 0.0
    for i in range(d):
        for j in range(d):
            v = A[i, j]
            if i == j and i > 0:
                v += gamma
            LU[i, j] = v
            if abs(v) > colscale[j]:
                colscale[j] = abs(v)
    for k in range(d):
        if colscale[k] == 0.0 or not math.isfinite(colscale[k]):
            return False
    for k in range(d):
        if not abs(LU[k, k]) > _PIVOT_REL * colscale[k]:
            return False
        for i in range(k + 1, d):
            f = LU[i, k] / LU[k, k]
            LU[i, k] = f
            for j in range(k + 1, d):
                LU[i, j] -= f * LU[k, j]
    return True


@numba.njit(cache=True, error_model="numpy")
def _lu_solve(LU, b, sign, x):
    """Solve ``(LU) x = sign · b`` into ``x`` with the factors of :func:`_lu_factor`."""
    d = LU.shape[0]
    for i in range(d):
        s = sign * b[i]
        for j in range(i):
            s -= LU[i, j] * x[j]
        x[i] = s
    for i in range(d - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, d):
            s -= LU[i, j] * x[j]
        x[i] = s / LU[i, i]


@numba.njit(cache=True, error_model="numpy")
def _lu_solve_t(LU, b, x, y):
    """Solve ``Aᵀ x = b`` with the factors ``A = L U`` of :func:`_lu_factor` (``y``: workspace)."""
    d = LU.shape[0]
    for i in range(d):  # Uᵀ y = b
        s = b[i]
        for j in range(i):
            s -= LU[j, i] * y[j]
        y[i] = s / LU[i, i]
    for i in range(d - 1, -1, -1):  # Lᵀ w = y (unit diagonal)
        s = y[i]
        for j in range(i + 1, d):
            s -= LU[j, i] * y[j]
        y[i] = s
    for i in range(d):
        x[i] = y[i]


# --------------------------------------------------------------------------- cone helpers


@numba.njit(cache=True, error_model="numpy")
def _tangent_norm(x):
    """``‖x_t‖`` without underflow or overflow (scaled by ``max|x_t|``, like ``hypot``)."""
    s = 0.0
    for i in range(1, x.shape[0]):
        s += x[i] * x[i]
    if 1e-290 < s < 1e290:  # the plain sum lost nothing
        return math.sqrt(s)
    big = 0.0
    for i in range(1, x.shape[0]):
        big = max(big, abs(x[i]))
    if big == 0.0 or not math.isfinite(big):
        return big
    s = 0.0
    for i in range(1, x.shape[0]):
        t = x[i] / big
        s += t * t
    return big * math.sqrt(s)


@numba.njit(cache=True, error_model="numpy")
def project_cone_into(x, mu, out):
    """Euclidean projection of ``x = (x_n, x_t)`` onto ``K_μ``, written into ``out``.

    Parameters
    ----------
    x : ndarray, shape (d,)
        Point to project, normal component first.
    mu : float
        Friction coefficient ``μ ≥ 0`` (``μ = 0`` is the ray ``{x_t = 0, x_n ≥ 0}``).
    out : ndarray, shape (d,)
        Receives ``Proj_{K_μ}(x)``; may be the same array as ``x``.
    """
    d = x.shape[0]
    xn = x[0]
    nt = _tangent_norm(x)
    if not (math.isfinite(xn) and math.isfinite(nt)):
        for i in range(d):  # propagate: callers detect non-finite values
            out[i] = x[i] + 0.0 * xn
        return
    if mu * nt <= -xn:
        for i in range(d):
            out[i] = 0.0
    elif nt <= mu * xn:
        for i in range(d):
            out[i] = x[i]
    else:
        pn = (xn + mu * nt) / (1.0 + mu * mu)
        f = mu * pn / nt
        out[0] = pn
        for i in range(1, d):
            out[i] = f * x[i]


@numba.njit(cache=True, error_model="numpy")
def project_cone(x, mu):
    """Euclidean projection of ``x`` onto the Coulomb cone ``K_μ`` (docs/math.md formula).

    Parameters
    ----------
    x : ndarray, shape (d,)
        Point ``(x_n, x_t)``.
    mu : float
        Friction coefficient.

    Returns
    -------
    ndarray, shape (d,)
        ``Proj_{K_μ}(x)``.
    """
    out = np.empty(x.shape[0])
    project_cone_into(x, mu, out)
    return out


@numba.njit(cache=True, error_model="numpy")
def _natural_map_sq(W, alpha, mu, P, u, tmp):
    """Squared natural-map residual ``‖P − Proj_K(P − ũ)‖²`` of one contact (fills ``u``)."""
    d = alpha.shape[0]
    for i in range(d):
        s = alpha[i]
        for j in range(d):
            s += W[i, j] * P[j]
        u[i] = s
    ut = _tangent_norm(u)
    tmp[0] = P[0] - (u[0] + mu * ut)
    for i in range(1, d):
        tmp[i] = P[i] - u[i]
    project_cone_into(tmp, mu, tmp)
    e = 0.0
    for i in range(d):
        e += (P[i] - tmp[i]) ** 2
    return e


# --------------------------------------------------------------------------- general cone


@numba.njit(cache=True, error_model="numpy")
def _phi(A, alpha, mu, gamma, LU, colscale, P, dP, b):
    """``φ(γ) = ‖P_t(γ)‖ − μ P_n(γ)`` and ``φ'(γ)``; fills ``P``; ok flag first."""
    d = alpha.shape[0]
    if not _lu_factor(A, gamma, LU, colscale):
        return False, 0.0, 0.0
    _lu_solve(LU, alpha, -1.0, P)
    # dP/dγ = −(A + γE_t)⁻¹ E_t P, same factors
    b[0] = 0.0
    for i in range(1, d):
        b[i] = P[i]
    _lu_solve(LU, b, -1.0, dP)
    nt = _tangent_norm(P)
    phi = nt - mu * P[0]
    if nt > 0.0:
        dt = 0.0
        for i in range(1, d):
            dt += P[i] * dP[i]
        dphi = dt / nt - mu * dP[0]
    else:
        dphi = -mu * dP[0]
    ok = math.isfinite(phi) and math.isfinite(dphi)
    return ok, phi, dphi


@numba.njit(cache=True, error_model="numpy")
def _polish(A, mu, P, LU, colscale, z, y, g, ytmp):
    """Cancel the cone-membership error of a sliding ``P`` at the least change of ``u``.

    ``P(γ)`` from an ill-conditioned ``W + γE_t`` is backward stable (``u`` accurate) but
    ``φ = ‖P_t‖ − μP_n`` carries a rounding error of order ``cond(W)·ε·‖P‖``. The correction
    ``δP = −φ (WᵀW)⁻¹g / (gᵀ(WᵀW)⁻¹g)`` with ``g = ∇φ`` removes it to first order while moving
    ``u = WP + α`` by only ``|φ| / ‖W⁻ᵀg‖``. Skipped when ``W`` is singular.
    """
    d = P.shape[0]
    nt = _tangent_norm(P)
    if nt == 0.0 or not _lu_factor(A, 0.0, LU, colscale):
        return
    phi = nt - mu * P[0]
    g[0] = -mu
    for i in range(1, d):
        g[i] = P[i] / nt
    _lu_solve_t(LU, g, z, ytmp)
    _lu_solve(LU, z, 1.0, y)
    zz = 0.0
    yy = 0.0
    pp = 0.0
    for i in range(d):
        zz += z[i] * z[i]
        yy += y[i] * y[i]
        pp += P[i] * P[i]
    if not (zz > 0.0 and math.isfinite(zz) and math.isfinite(yy)):
        return
    f = -phi / zz
    if f * f * yy > 1e-6 * pp:  # not a rounding-size correction: leave P alone
        return
    for i in range(d):
        P[i] += f * y[i]


@numba.njit(cache=True, error_model="numpy")
def _newton_psi(x, P, dP, mu):
    """Newton step on ``ψ(γ) = 1/‖P_t(γ)‖ − 1/(μ P_n(γ))`` (same root as ``φ``); −1 if undefined.

    For an isotropic block ``W = w I`` ``ψ`` is affine in ``γ`` (``‖P_t‖ = ‖α_t‖/(w + γ)``, ``P_n``
    constant), so Newton on ``ψ`` lands on the root in one step; for a general block it
    converges quadratically from much farther than Newton on ``φ``.
    """
    d = P.shape[0]
    nt = _tangent_norm(P)
    if not (P[0] > 0.0 and nt > 0.0 and mu > 0.0):
        return -1.0
    dt = 0.0
    for i in range(1, d):
        dt += (P[i] / nt) * (dP[i] / nt)
    psi = 1.0 / nt - 1.0 / (mu * P[0])
    dpsi = -dt / nt + dP[0] / (mu * P[0] * P[0])
    if not (dpsi != 0.0 and math.isfinite(dpsi) and math.isfinite(psi)):
        return -1.0
    return x - psi / dpsi


@numba.njit(cache=True, error_model="numpy")
def _slide_root(A, alpha, mu, P, ws):
    """Sliding regime by the root of ``φ(γ)``; returns ``(regime, iterations)``.

    ``regime`` is ``SLIDE``, or ``STICK`` when the root sits at ``γ ≈ 0`` (a singular ``W_jj``
    whose stick solution the LU could not produce directly), or ``FAILED``.
    """
    d = alpha.shape[0]
    LU = ws[0 : d * d].reshape((d, d))
    colscale = ws[16 : 16 + d]
    Pw = ws[20 : 20 + d]
    dP = ws[24 : 24 + d]
    b = ws[28 : 28 + d]
    # scale of γ: mean tangential diagonal of A (units of W)
    s = 0.0
    amax = 0.0
    for i in range(d):
        for j in range(d):
            if abs(A[i, j]) > amax:
                amax = abs(A[i, j])
    for i in range(1, d):
        s += abs(A[i, i])
    s /= d - 1
    if s <= 0.0:
        s = amax
    gamma_floor = 1e-14 * amax
    # first guess: the root for an isotropic block w I, w = s: ‖α_t‖/(s + γ) = μ p∞
    p_inf = -alpha[0] / A[0, 0]
    guess = _tangent_norm(alpha) / (mu * p_inf) - s
    # bracket: lo with φ > 0 (lo = 0 stands for the failed stick), hi with φ < 0
    lo = 0.0
    hi = guess if (math.isfinite(guess) and guess > 1e-3 * s) else s
    it = 0
    found_hi = False
    phi_hi = 0.0
    dphi_hi = 0.0
    while it < _MAX_ROOT_ITER:
        it += 1
        ok, phi, dphi = _phi(A, alpha, mu, hi, LU, colscale, Pw, dP, b)
        if ok and phi <= 0.0:
            found_hi = True
            phi_hi = phi
            dphi_hi = dphi
            break
        factor = 8.0
        if ok and hi >= 1e16 * amax and _slide_asymptotic(A, alpha, mu, P):
            # the root is so far out that ‖P‖ < 1e-16 ‖α‖/‖W‖: u_t = α_t to rounding
            return SLIDE, it
        if ok:
            lo = hi
            # for large γ, P(γ) ≈ P(∞) + c/γ with P(∞) = (p∞, 0), p∞ = −α_n/W_nn > 0, so
            # φ(γ) ≈ c'/γ − μ p∞ and the root is near γ (1 + φ(γ)/(μ p∞)): jump there
            p_inf = -alpha[0] / A[0, 0]
            if mu * p_inf > 0.0:
                jump = 2.0 * (1.0 + phi / (mu * p_inf))
                if math.isfinite(jump):
                    factor = max(factor, min(jump, 1e100))
        hi *= factor
        if hi > 1e300 or not math.isfinite(hi):
            break
    if not found_hi:
        return FAILED, it
    for i in range(d):
        P[i] = Pw[i]
    if phi_hi == 0.0:
        return SLIDE, it
    x = hi
    phi_x = phi_hi
    dphi_x = dphi_hi
    phi_p = phi_hi  # φ at the point stored in P (always the latest φ ≤ 0 point, or better)
    force_bisect = False
    while it < _MAX_ROOT_ITER:
        it += 1
        base = max(lo, gamma_floor)
        if hi <= base * (1.0 + 8.0 * _EPS):
            break  # bracket collapsed onto the singular floor
        # candidate: Newton step on ψ (else on φ) from the current point, else bisection
        xn = -1.0
        newton_ok = False
        if not force_bisect:
            xn = _newton_psi(x, Pw, dP, mu)
            newton_ok = xn > base and xn < hi
            if not newton_ok and dphi_x != 0.0 and math.isfinite(dphi_x):
                xn = x - phi_x / dphi_x
                newton_ok = xn > base and xn < hi
        if newton_ok and abs(xn - x) <= 4.0 * _EPS * x:
            break  # Newton step below rounding: converged
        if not (xn > base and xn < hi):
            if lo > 0.0:
                xn = math.sqrt(lo) * math.sqrt(hi) if hi > 4.0 * lo else 0.5 * (lo + hi)
            else:
                xn = hi / 64.0
            xn = max(xn, gamma_floor)
        ok, phi, dphi = _phi(A, alpha, mu, xn, LU, colscale, Pw, dP, b)
        if not ok:
            # W + γE_t singular to working precision: γ ≤ xn is numerically γ = 0
            gamma_floor = xn
            force_bisect = True
            continue
        force_bisect = abs(phi) > 0.5 * abs(phi_x)
        x = xn
        phi_x = phi
        dphi_x = dphi
        nt = _tangent_norm(Pw)
        if phi <= 0.0:
            hi = x
        else:
            lo = x
        if phi <= 0.0 or abs(phi) < abs(phi_p):
            phi_p = phi
            for i in range(d):
                P[i] = Pw[i]
        if abs(phi) <= 4.0 * _EPS * (nt + mu * abs(Pw[0])):
            break
        if lo > 0.0 and hi - lo <= 4.0 * _EPS * hi:
            break
    if lo < gamma_floor and hi <= gamma_floor * (1.0 + 8.0 * _EPS) and phi_p < 0.0:
        # P(γ) stayed inside the cone down to γ ≈ 0: a stick solution of a singular W_jj if
        # u = −γ E_t P is negligible; otherwise P(γ) diverges (no finite solution exists).
        ut = _tangent_norm(P) * hi
        an = 0.0
        for i in range(d):
            an += alpha[i] * alpha[i]
        if ut <= 1e-8 * math.sqrt(an) and P[0] >= 0.0:
            return STICK, it
        return FAILED, it
    if P[0] >= 0.0:
        for i in range(d):
            Pw[i] = P[i]
        nt = _tangent_norm(P)
        if abs(nt - mu * P[0]) > 16.0 * _EPS * (nt + mu * P[0]):
            # φ is not at rounding level (ill-conditioned block): correct it where u moves least
            _polish(A, mu, P, LU, colscale, b, dP, ws[32 : 32 + d], ws[36 : 36 + d])
        # exact cone membership: put P_t on the surface ‖P_t‖ = μ P_n
        nt = _tangent_norm(P)
        if nt > 0.0:
            f = mu * P[0] / nt
            for i in range(1, d):
                P[i] *= f
        if _slide_is_sound(A, alpha, P):
            return SLIDE, it
        for i in range(d):
            P[i] = Pw[i]
    # closed-form fallback: keep the sliding direction of the root, solve u_n = 0 for P_n
    if _slide_from_direction(A, alpha, mu, P):
        return SLIDE, it
    return FAILED, it


@numba.njit(cache=True, error_model="numpy")
def _slide_asymptotic(A, alpha, mu, P):
    """Sliding along ``ŝ = α_t/‖α_t‖`` (exact when ``‖W P‖ ≪ ‖α_t‖``); ``False`` if unsound."""
    d = alpha.shape[0]
    for i in range(d):
        P[i] = -alpha[i] if i > 0 else 0.0
    return _slide_from_direction(A, alpha, mu, P)


@numba.njit(cache=True, error_model="numpy")
def _slide_from_direction(A, alpha, mu, P):
    """Sliding impulse for the direction of ``P_t``: ``P = P_n (1, −μ ŝ)``, ``u_n = 0``.

    ``ŝ = −P_t/‖P_t‖`` is the sliding direction; ``P_n = −α_n / (W_nn − μ W_nt·ŝ)``. Used when
    rounding spoiled ``P_n`` at the root (e.g. ``|α_n| ≪ ‖α_t‖`` by 150 orders of magnitude,
    where ``γ`` is so large that ``P(γ)`` underflows). Returns ``False`` if not sound.
    """
    d = alpha.shape[0]
    nt = _tangent_norm(P)
    if not (nt > 0.0 and math.isfinite(nt)):
        return False
    den = A[0, 0]
    for i in range(1, d):
        den += mu * A[0, i] * P[i] / nt
    if not den > 0.0:
        return False
    pn = -alpha[0] / den
    f = mu * pn / nt
    for i in range(1, d):
        P[i] *= f
    P[0] = pn
    return pn >= 0.0 and _slide_is_sound(A, alpha, P)


@numba.njit(cache=True, error_model="numpy")
def _slide_is_sound(A, alpha, P):
    """Backward check of a sliding ``P``: ``u_n ≈ 0`` and ``u_t`` opposes ``P_t``.

    Guards against a root that is an artefact of rounding (no finite solution exists for some
    singular ``W_jj``): accepted when ``|u_n|`` and the part of ``u_t`` along ``P_t`` are below
    ``1e-9 (‖α‖ + max|W| ‖P‖)``.
    """
    d = alpha.shape[0]
    amax = 0.0
    pp = 0.0
    aa = 0.0
    for i in range(d):
        pp += P[i] * P[i]
        aa += alpha[i] * alpha[i]
        for j in range(d):
            amax = max(amax, abs(A[i, j]))
    scale = math.sqrt(aa) + amax * math.sqrt(pp)
    un = alpha[0]
    along = 0.0
    for j in range(d):
        un += A[0, j] * P[j]
    for i in range(1, d):
        ui = alpha[i]
        for j in range(d):
            ui += A[i, j] * P[j]
        along += ui * P[i]
    nt = _tangent_norm(P)
    if nt > 0.0:
        along /= nt
    ok = abs(un) <= 1e-9 * scale and along <= 1e-9 * scale
    return ok and math.isfinite(scale)


@numba.njit(cache=True, error_model="numpy")
def _fallback(A, alpha, mu, P, ws):
    """No regime established: the least-residual finite candidate among open and normal-only."""
    d = alpha.shape[0]
    u = ws[60 : 60 + d]
    tmp = ws[64 : 64 + d]
    cand = ws[68 : 68 + d]
    for i in range(d):
        P[i] = 0.0
        cand[i] = 0.0
    best = _natural_map_sq(A, alpha, mu, P, u, tmp)
    if A[0, 0] > 0.0:
        cand[0] = max(0.0, -alpha[0] / A[0, 0])
        if not math.isfinite(cand[0]):
            return
        e = _natural_map_sq(A, alpha, mu, cand, u, tmp)
        if e < best:
            for i in range(d):
                P[i] = cand[i]


@numba.njit(cache=True, error_model="numpy")
def _normalized_solve(A, alpha, mu, P, planar, ws):
    """Run a core solver on ``(W/max|W|, α/max|α|)`` and scale ``P`` back (homogeneity)."""
    d = alpha.shape[0]
    amax = 0.0
    alm = 0.0
    for i in range(d):
        alm = max(alm, abs(alpha[i]))
        for j in range(d):
            amax = max(amax, abs(A[i, j]))
    if not (amax > 0.0 and alm > 0.0 and math.isfinite(amax) and math.isfinite(alm)):
        if planar:
            return _coulomb_2d_core(A, alpha, mu, P, ws)
        return _cone_solve_core(A, alpha, mu, P, ws)
    As = ws[40 : 40 + d * d].reshape((d, d))
    als = ws[56 : 56 + d]
    for i in range(d):
        als[i] = alpha[i] / alm
        for j in range(d):
            As[i, j] = A[i, j] / amax
    if planar:
        regime, it = _coulomb_2d_core(As, als, mu, P, ws)
    else:
        regime, it = _cone_solve_core(As, als, mu, P, ws)
    for i in range(d):
        P[i] = (P[i] * alm) / amax if alm < amax else P[i] * (alm / amax)
    for i in range(d):
        if not math.isfinite(P[i]):
            _fallback(A, alpha, mu, P, ws)
            return FAILED, it
    return regime, it


@numba.njit(cache=True, error_model="numpy")
def cone_solve_into(A, alpha, mu, P):
    """Solve the one-contact law in a ``(1+k)``-dimensional Coulomb cone, in place.

    The data are first normalized (``W / max|W|``, ``α / max|α|``; the law is homogeneous in
    both), so that no intermediate quantity overflows or underflows.

    Parameters
    ----------
    A : ndarray, shape (d, d)
        Diagonal Delassus block ``W_jj``, ``d = 1 + k`` with ``k ∈ {1, 2, 3}``.
    alpha : ndarray, shape (d,)
        Free velocity ``α̂_j``.
    mu : float
        Friction coefficient ``μ ≥ 0``.
    P : ndarray, shape (d,)
        Receives the impulse.

    Returns
    -------
    regime : int
        ``OPEN``, ``STICK``, ``SLIDE`` or ``FAILED`` (the contact's regime, not a solve status).
    iterations : int
        Root-finding iterations (0 for the closed-form regimes).
    """
    return _normalized_solve(A, alpha, mu, P, False, np.empty(WORKSPACE_SIZE))


@numba.njit(cache=True, error_model="numpy")
def cone_solve_ws(A, alpha, mu, P, ws):
    """:func:`cone_solve_into` with a caller-owned workspace (``WORKSPACE_SIZE`` floats).

    For compiled loops over many contacts: no heap allocation per call.
    """
    return _normalized_solve(A, alpha, mu, P, False, ws)


@numba.njit(cache=True, error_model="numpy")
def _cone_solve_core(A, alpha, mu, P, ws):
    """:func:`cone_solve_into` on normalized data (same arguments and returns)."""
    d = alpha.shape[0]
    if alpha[0] >= 0.0:
        for i in range(d):
            P[i] = 0.0
        return OPEN, 0
    amax = 0.0
    for i in range(d):
        for j in range(d):
            if abs(A[i, j]) > amax:
                amax = abs(A[i, j])
    if not (A[0, 0] > _PIVOT_REL * amax) or not math.isfinite(amax):
        _fallback(A, alpha, mu, P, ws)
        return FAILED, 0
    if mu <= _MU_ZERO:
        P[0] = -alpha[0] / A[0, 0]
        for i in range(1, d):
            P[i] = 0.0
        return SLIDE, 0
    LU = ws[0 : d * d].reshape((d, d))
    if _lu_factor(A, 0.0, LU, ws[16 : 16 + d]):
        _lu_solve(LU, alpha, -1.0, P)
        if P[0] >= 0.0 and _tangent_norm(P) <= mu * P[0]:
            return STICK, 0
    regime, it = _slide_root(A, alpha, mu, P, ws)
    if regime != FAILED:
        return regime, it
    _fallback(A, alpha, mu, P, ws)
    return FAILED, it


@numba.njit(cache=True, error_model="numpy")
def _coulomb_2d_core(A, alpha, mu, P, ws):
    """:func:`coulomb_2d_into` on normalized data (same arguments and returns)."""
    if alpha[0] >= 0.0:
        P[0] = 0.0
        P[1] = 0.0
        return OPEN, 0
    amax = max(max(abs(A[0, 0]), abs(A[0, 1])), max(abs(A[1, 0]), abs(A[1, 1])))
    if not (A[0, 0] > _PIVOT_REL * amax) or not math.isfinite(amax):
        _fallback(A, alpha, mu, P, ws)
        return FAILED, 0
    if mu <= _MU_ZERO:
        P[0] = -alpha[0] / A[0, 0]
        P[1] = 0.0
        return SLIDE, 0
    det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    if abs(det) > _PIVOT_REL * amax * amax:
        pn = -(A[1, 1] * alpha[0] - A[0, 1] * alpha[1]) / det
        pt = -(-A[1, 0] * alpha[0] + A[0, 0] * alpha[1]) / det
        if pn >= 0.0 and abs(pt) <= mu * pn:
            P[0] = pn
            P[1] = pt
            return STICK, 0
    for k in range(2):
        s = 1.0 if k == 0 else -1.0  # sliding direction sign(u_t); P_t = −s μ P_n
        den = A[0, 0] - s * mu * A[0, 1]
        if den > 0.0:
            pn = -alpha[0] / den
            pt = -s * mu * pn
            ut = A[1, 0] * pn + A[1, 1] * pt + alpha[1]
            if s * ut >= 0.0:
                P[0] = pn
                P[1] = pt
                return SLIDE, 0
    regime, it = _slide_root(A, alpha, mu, P, ws)
    if regime != FAILED:
        return regime, it
    _fallback(A, alpha, mu, P, ws)
    return FAILED, it


@numba.njit(cache=True, error_model="numpy")
def coulomb_2d_into(A, alpha, mu, P):
    """Closed-form 2D Coulomb one-contact solver (open / stick / slide ±), in place.

    Parameters
    ----------
    A : ndarray, shape (2, 2)
        Diagonal Delassus block, order ``(n, t)``.
    alpha : ndarray, shape (2,)
        Free velocity.
    mu : float
        Friction coefficient ``μ ≥ 0``.
    P : ndarray, shape (2,)
        Receives the impulse ``(P_n, P_t)``.

    Returns
    -------
    regime : int
        ``OPEN``, ``STICK``, ``SLIDE`` or ``FAILED`` (the contact's regime, not a solve status).
    iterations : int
        0, unless rounding rejected every closed-form regime and the root find ran.
    """
    return _normalized_solve(A, alpha, mu, P, True, np.empty(WORKSPACE_SIZE))


@numba.njit(cache=True, error_model="numpy")
def coulomb_2d_ws(A, alpha, mu, P, ws):
    """:func:`coulomb_2d_into` with a caller-owned workspace (``WORKSPACE_SIZE`` floats)."""
    return _normalized_solve(A, alpha, mu, P, True, ws)


@numba.njit(cache=True, error_model="numpy")
def soft_finger_into(A, alpha, mu, torsion_radius, P):
    """Soft-finger (elliptic, condim 4) one-contact solver by scaling, in place.

    Parameters
    ----------
    A : ndarray, shape (4, 4)
        Diagonal Delassus block, order ``(n, t1, t2, spin)``.
    alpha : ndarray, shape (4,)
        Free velocity ``(u_n, u_t1, u_t2, ω_n)`` [m/s, m/s, m/s, rad/s].
    mu : float
        Friction coefficient.
    torsion_radius : float
        ``e_r ≥ 0`` [m]; the spin impulse obeys ``|P_s| ≤ e_r μ P_n`` at ``P_t = 0``.
    P : ndarray, shape (4,)
        Receives ``(P_n, P_t1, P_t2, P_s)`` [N·s, N·s, N·s, N·m·s].

    Returns
    -------
    regime, iterations : int
        As :func:`cone_solve_into`.
    """
    As = np.empty((4, 4))
    al = np.empty(4)
    sc = np.array([1.0, 1.0, 1.0, torsion_radius])
    for i in range(4):
        al[i] = sc[i] * alpha[i]
        for j in range(4):
            As[i, j] = sc[i] * A[i, j] * sc[j]
    regime, it = cone_solve_into(As, al, mu, P)
    P[3] *= torsion_radius
    return regime, it


# --------------------------------------------------------------------------- public wrappers


@numba.njit(cache=True, error_model="numpy")
def solve_cone(W, alpha, mu):
    """Exact one-contact solver for a ``(1+k)``-dimensional Coulomb cone, ``k = 1, 2, 3``.

    Parameters
    ----------
    W : ndarray, shape (d, d)
        Diagonal Delassus block ``W_jj`` (positive definite, or PSD with ``W_nn > 0``).
    alpha : ndarray, shape (d,)
        Free velocity ``α̂_j``, normal first.
    mu : float
        Friction coefficient ``μ ≥ 0``.

    Returns
    -------
    P : ndarray, shape (d,)
        Impulse satisfying the law.
    regime : int
        ``OPEN``, ``STICK``, ``SLIDE`` or ``FAILED`` (the contact's regime, not a solve status).
    iterations : int
        Root-finding iterations.
    """
    P = np.empty(alpha.shape[0])
    regime, it = cone_solve_into(W, alpha, mu, P)
    return P, regime, it


@numba.njit(cache=True, error_model="numpy")
def solve_coulomb_2d(W, alpha, mu):
    """Exact 2D Coulomb one-contact solver (closed form by enumeration).

    Parameters
    ----------
    W : ndarray, shape (2, 2)
        Diagonal Delassus block, order ``(n, t)``.
    alpha : ndarray, shape (2,)
        Free velocity.
    mu : float
        Friction coefficient ``μ ≥ 0``.

    Returns
    -------
    P : ndarray, shape (2,)
        Impulse ``(P_n, P_t)``.
    regime : int
        ``OPEN``, ``STICK``, ``SLIDE`` or ``FAILED`` (the contact's regime, not a solve status).
    iterations : int
        0 for the closed forms.
    """
    P = np.empty(2)
    regime, it = coulomb_2d_into(W, alpha, mu, P)
    return P, regime, it


@numba.njit(cache=True, error_model="numpy")
def solve_coulomb_3d(W, alpha, mu):
    """Exact 3D Coulomb one-contact solver (second-order cone, no linearization).

    Parameters
    ----------
    W : ndarray, shape (3, 3)
        Diagonal Delassus block, order ``(n, t1, t2)``.
    alpha : ndarray, shape (3,)
        Free velocity.
    mu : float
        Friction coefficient ``μ ≥ 0``.

    Returns
    -------
    P : ndarray, shape (3,)
        Impulse ``(P_n, P_t1, P_t2)``.
    regime : int
        ``OPEN``, ``STICK``, ``SLIDE`` or ``FAILED`` (the contact's regime, not a solve status).
    iterations : int
        Root-finding iterations of the sliding case.
    """
    P = np.empty(3)
    regime, it = cone_solve_into(W, alpha, mu, P)
    return P, regime, it


@numba.njit(cache=True, error_model="numpy")
def solve_soft_finger(W, alpha, mu, torsion_radius):
    """Exact soft-finger one-contact solver (ellipsoid [10] with ``e_x = e_y = 1``).

    Parameters
    ----------
    W : ndarray, shape (4, 4)
        Diagonal Delassus block, order ``(n, t1, t2, spin)``.
    alpha : ndarray, shape (4,)
        Free velocity.
    mu : float
        Friction coefficient ``μ ≥ 0``.
    torsion_radius : float
        ``e_r ≥ 0`` [m].

    Returns
    -------
    P : ndarray, shape (4,)
        Impulse ``(P_n, P_t1, P_t2, P_s)``.
    regime : int
        ``OPEN``, ``STICK``, ``SLIDE`` or ``FAILED`` (the contact's regime, not a solve status).
    iterations : int
        Root-finding iterations of the sliding case.
    """
    P = np.empty(4)
    regime, it = soft_finger_into(W, alpha, mu, torsion_radius, P)
    return P, regime, it


# ------------------------------------------------- shortcuts the time step tries before the solvers
_SLIDE_NEWTON_ITER = 16


@numba.njit(cache=True)
def open_or_stick(alpha, mu, d, inv, has_inv, P):
    """The open and stick regimes in closed form when they hold clearly; False: use the full solver.

    Open: ``α_n ≥ 0`` gives ``P = 0`` exactly (the local solver's first regime). Stick:
    ``P = −W_jj⁻¹ α`` is accepted only strictly inside the cone (a relative margin of 1e-9), so
    every boundary case still goes to the exact solver.
    """
    if alpha[0] >= 0.0:
        for a in range(d):
            P[a] = 0.0
        return True
    if not has_inv:
        return False
    for a in range(d):
        acc = 0.0
        for b in range(d):
            acc -= inv[a, b] * alpha[b]
        P[a] = acc
    if P[0] <= 0.0:
        return False
    nt = 0.0
    for a in range(1, d):
        nt += P[a] * P[a]
    return math.sqrt(nt) < mu * P[0] * (1.0 - 1e-9)


@numba.njit(cache=True)
def slide3_newton(A, alpha, mu, P):
    """The sliding regime of a 3D contact by Newton on the slip direction, started from ``P``'s.

    Sliding means ``u_n = 0``, ``P_t = −μ P_n s`` and ``u_t = g s`` with ``g > 0`` for a unit
    ``s = (cos θ, sin θ)``. For a given ``s`` the first condition gives
    ``P_n = −α_n / (W_nn − μ W_nt·s)``, so the law is the scalar equation
    ``f(θ) = u_t × s = 0`` (with ``g = u_t·s > 0``), and ``f'(θ) = (du_t/dθ) × s + g`` exactly.
    Newton's step ``δ = f/f'`` turns ``s`` by ``atan δ`` (``s ← (s − δ s⊥)/√(1 + δ²)``: no
    trigonometry; still quadratic). Started from the previous sweep's (or step's) slip direction
    it converges in 2–3 steps, a fraction of the general root find of :mod:`.local`. The result is
    accepted only when the last step is below 1e-14 rad, ``D``, ``P_n`` and the slip ``g`` are
    clearly positive (``g > 1e-9‖α‖``, so a contact at the stick/slide boundary goes to the
    general solver) and everything is finite; otherwise ``False`` and the caller uses the general
    solver. No cone is linearized: the root is of the exact law.
    """
    an = alpha[0]
    if not (an < 0.0) or not (mu > 1e-17):
        return False
    a = A[0, 0]
    b0 = A[0, 1]
    b1 = A[0, 2]
    c0 = A[1, 0]
    c1 = A[2, 0]
    C00 = A[1, 1]
    C01 = A[1, 2]
    C10 = A[2, 1]
    C11 = A[2, 2]
    a1 = alpha[1]
    a2 = alpha[2]
    s0, s1 = -P[1], -P[2]  # u_t opposes P_t
    ns = math.sqrt(s0 * s0 + s1 * s1)
    if not (ns > 0.0) or not math.isfinite(ns):
        s0, s1 = a1, a2
        ns = math.sqrt(s0 * s0 + s1 * s1)
        if not (ns > 0.0) or not math.isfinite(ns):
            return False
    s0 /= ns
    s1 /= ns
    scale = abs(an) + abs(a1) + abs(a2)
    for _ in range(_SLIDE_NEWTON_ITER):
        D = a - mu * (b0 * s0 + b1 * s1)
        if not (D > 0.0):
            return False
        Pn = -an / D
        k0 = c0 - mu * (C00 * s0 + C01 * s1)
        k1 = c1 - mu * (C10 * s0 + C11 * s1)
        ut0 = k0 * Pn + a1
        ut1 = k1 * Pn + a2
        f = ut0 * s1 - ut1 * s0
        g = ut0 * s0 + ut1 * s1
        dPn = -an * mu * (b1 * s0 - b0 * s1) / (D * D)
        dut0 = k0 * dPn - mu * Pn * (C01 * s0 - C00 * s1)
        dut1 = k1 * dPn - mu * Pn * (C11 * s0 - C10 * s1)
        df = dut0 * s1 - dut1 * s0 + g
        if not (df > 0.0) or not math.isfinite(df):
            return False
        delta = f / df
        if abs(delta) <= 1e-14:
            if not (g > 1e-9 * scale) or not (Pn > 0.0) or not math.isfinite(Pn):
                return False
            P[0] = Pn
            P[1] = -mu * Pn * s0
            P[2] = -mu * Pn * s1
            return True
        r = 1.0 / math.sqrt(1.0 + delta * delta)
        s0, s1 = (s0 + delta * s1) * r, (s1 - delta * s0) * r
    return False


# --------------------------------------------------------------------------- checks (NumPy)


def _norm(x: np.ndarray) -> float:
    """Euclidean norm without under/overflow of the squares."""
    big = float(np.max(np.abs(x))) if x.size else 0.0
    return big * float(np.linalg.norm(x / big)) if big > 0.0 else 0.0


def law_violation(
    W: np.ndarray,
    alpha: np.ndarray,
    mu: float,
    P: np.ndarray,
    torsion_radius: float | None = None,
) -> float:
    """Scale-free violation of the one-contact law by ``P`` (0 when it holds exactly).

    Plain NumPy, independent of the compiled solvers. With ``ũ = u + μ‖u_t‖ e_n`` and
    ``u = W P + α``, it is the largest of the cone violation ``max(0, ‖P_t‖ − μ P_n, −P_n)/‖P‖``,
    the dual-cone violation ``max(0, −u_n)/s_u`` and the complementarity ``|P·ũ|/(‖P‖ s_u)``,
    with the velocity scale ``s_u = max(‖ũ‖, ‖α‖, ‖W‖‖P‖)``. For a soft finger (``d = 4`` with
    ``torsion_radius``) the check runs in the scaled variables of the module docstring.

    Parameters
    ----------
    W : ndarray, shape (d, d)
        Diagonal Delassus block.
    alpha : ndarray, shape (d,)
        Free velocity.
    mu : float
        Friction coefficient.
    P : ndarray, shape (d,)
        Impulse to check.
    torsion_radius : float, optional
        ``e_r`` for a soft finger.

    Returns
    -------
    float
        The violation, relative.
    """
    W = np.asarray(W, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    P = np.asarray(P, dtype=float)
    if torsion_radius is not None:
        s = np.array([1.0, 1.0, 1.0, float(torsion_radius)])
        W = s[:, None] * W * s[None, :]
        alpha = s * alpha
        P = P / np.where(s > 0, s, 1.0)
    # the law is homogeneous: normalize so that no square below under- or overflows
    c_w = float(np.max(np.abs(W))) or 1.0
    c_a = max(float(np.max(np.abs(alpha))), c_w * float(np.max(np.abs(P)))) or 1.0
    W, alpha, P = W / c_w, alpha / c_a, (P / c_a) * c_w
    u = W @ P + alpha
    u_mod = u.copy()
    u_mod[0] += mu * _norm(u[1:])
    norm_p = _norm(P)
    s_u = max(_norm(u_mod), _norm(alpha), float(np.linalg.norm(W, 2)) * norm_p) or 1.0
    if norm_p == 0.0:
        return max(0.0, -u[0]) / s_u
    p = P / norm_p
    cone = max(0.0, _norm(p[1:]) - mu * p[0], -p[0])
    dual = max(0.0, -u[0]) / s_u
    comp = abs(float(p @ (u_mod / s_u)))
    return max(cone, dual, comp)
