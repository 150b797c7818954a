"""The Siconos/FCLib residual of a frictional contact problem, compiled: what every sweep stops on.

For ``u = W r + q`` and contacts ``j`` with rows ``o_j : o_j + d_j`` (natural map, ``ρ = 1``)::

    err = sqrt(Σ_j ‖r_j − Proj_{K_μj}(r_j − u_j − μ_j‖u_t,j‖ e_n)‖²) / max(‖q‖, ‖r‖, ‖u‖)

(0 when the denominator is 0). :func:`fclib_error_rows` is the compiled one the sweeps (sparse
and dense) and the polish stop on; the plain NumPy version on a
:class:`~fixplan.engine.problem.ContactProblem` (in its scaled variables, so soft fingers see a
standard cone), the independent check of every solver, is
:func:`fixplan.engine.problem.fclib_error`. ``tests/engine/test_residual.py`` pins the two together.
"""

from __future__ import annotations

import math

from numba import njit

from fixplan.engine.local import project_cone_into


@njit(cache=True)
def fclib_error_rows(q, mu, offsets, sizes, nc, m, P, u, x, pr):
    """The FCLib residual of :func:`~fixplan.engine.problem.fclib_error`, compiled, on the leading ``nc`` contacts / ``m`` rows.

    ``u = W P + q`` is given (the caller computes it from its own ``W``, dense or sparse);
    ``offsets``/``sizes`` locate each contact's rows; ``x`` and ``pr`` are caller-owned scratch
    vectors of length 4 (no allocation). Standard cones only (soft-finger rows already scaled).
    """
    total = 0.0
    for j in range(nc):
        o, d = offsets[j], sizes[j]
        nt = 0.0
        for a in range(1, d):
            nt += u[o + a] * u[o + a]
        nt = math.sqrt(nt)
        x[0] = P[o] - (u[o] + mu[j] * nt)
        for a in range(1, d):
            x[a] = P[o + a] - u[o + a]
        if d == 3:
            # project_cone_into's arithmetic in scalars for the usual range of ‖x_t‖²
            x0, x1, x2 = x[0], x[1], x[2]
            st = x1 * x1 + x2 * x2
            if 1e-290 < st < 1e290 and math.isfinite(x0):
                m_ = mu[j]
                xt = math.sqrt(st)
                if m_ * xt <= -x0:
                    p0, p1, p2 = 0.0, 0.0, 0.0
                elif xt <= m_ * x0:
                    p0, p1, p2 = x0, x1, x2
                else:
                    p0 = (x0 + m_ * xt) / (1.0 + m_ * m_)
                    f = m_ * p0 / xt
                    p1, p2 = f * x1, f * x2
                d0, d1, d2 = P[o] - p0, P[o + 1] - p1, P[o + 2] - p2
                total += d0 * d0
                total += d1 * d1
                total += d2 * d2
                continue
        project_cone_into(x[:d], mu[j], pr[:d])
        for a in range(d):
            diff = P[o + a] - pr[a]
            total += diff * diff
    sq = 0.0
    sp = 0.0
    su = 0.0
    for r in range(m):
        sq += q[r] * q[r]
        sp += P[r] * P[r]
        su += u[r] * u[r]
    scale = max(math.sqrt(sq), max(math.sqrt(sp), math.sqrt(su)))
    return math.sqrt(total) / scale if scale > 0.0 else math.sqrt(total)
