"""The path program's derivatives, assembled from one knot's, equal CasADi's of the whole program.

The fine planner hands IPOPT the rows, their Jacobian and the Lagrangian's Hessian built from one
knot's rows (``_PathDerivatives``). Here a small program with the same structure (nonlinear knot
rows, rows that couple consecutive knots, two-knot no-slip rows with knot 0 fixed, slacks, a
quadratic objective) is built both ways and compared at random points: values, Jacobian and
Hessian to rounding, and the Jacobian against central differences too.
"""

import casadi as ca
import numpy as np
import pytest

from fixplan.planner.fine import _PathDerivatives

NV, K = 3, 4


def knot_rows():
    y = ca.SX.sym("y", NV)
    gap = ca.sin(y[0]) * y[1] + ca.exp(0.3 * y[2])
    bounds = ca.vertcat(y[0] ** 2 - y[1] * y[2], ca.cos(y[1] + y[2]))
    return ca.Function("knot_rows", [y], [gap, bounds])


def no_slip():
    ya, yb = ca.SX.sym("ya", NV), ca.SX.sym("yb", NV)
    rows = ca.vertcat(ca.sin(yb[0] - ya[0]) * yb[1], (yb[2] - ya[2]) * ya[1] + ya[0] * yb[0])
    return ca.Function("no_slip", [ya, yb], [rows])


def program(with_slip: bool, with_slack: bool, seed: int = 0):
    """(derivatives, reference x, f, g): the rows on placeholders and, for the reference, on the knots."""
    rng = np.random.default_rng(seed)
    kr, ns = knot_rows(), no_slip()
    Y = ca.SX.sym("Y", NV, K)
    y0 = rng.normal(size=NV)
    n_z = 3
    Z = ca.SX.sym("Z", n_z, K)
    W = ca.SX.sym("W", 2, K) if with_slip else ca.SX(0, K)
    S = ca.SX.sym("S", 2) if with_slack else None
    L, held, gap0 = 0.7, 0.05, 0.4

    def rows(z, w):
        """Affine rows like the planner's: scaled gaps, a clearance, a monotone chain, the no-slip rows."""
        out = []
        for k in range(K):
            out += [z[0, k] / L, (z[1, k] - held) / L, z[2, k] / L]
            out.append(((gap0 if k == 0 else z[0, k - 1]) - z[0, k]) / L)
            if with_slip:
                out += [w[0, k] / L, w[1, k] / L]
        out.append((z[0, K - 1] - 0.01) / L)
        if with_slack:
            out = [r + S[0] for r in out[:5]] + [S[1] - r for r in out[5:]] + [S[1] + r for r in out[5:]] + [S]
        return ca.vertcat(*out)

    g_placeholder = rows(Z, W)
    Wm = np.diag(rng.uniform(0.5, 2.0, NV))
    dY = Y - ca.horzcat(ca.DM(y0), Y[:, : K - 1])
    f = ca.sum2(ca.sum1(dY * ca.mtimes(ca.DM(Wm), dY))) + ca.dot(Y[:, -1] - 1.0, Y[:, -1] - 1.0)
    if S is not None:
        f = ca.sum1(S) + 0.1 * f
    derivs = _PathDerivatives(Y, S, Z, W, kr, ns if with_slip else None, y0, g_placeholder, f)
    # the reference: the same rows with every knot's functions inlined
    Z_real = ca.horzcat(*[ca.vertcat(*kr.call([Y[:, k]])) for k in range(K)])
    before = [ca.DM(y0)] + [Y[:, k] for k in range(K - 1)]
    W_real = ca.horzcat(*[ns.call([before[k], Y[:, k]])[0] for k in range(K)]) if with_slip else ca.SX(0, K)
    x = ca.vec(Y) if S is None else ca.vertcat(ca.vec(Y), S)
    return derivs, x, f, rows(Z_real, W_real)


@pytest.mark.parametrize("with_slip", [False, True])
@pytest.mark.parametrize("with_slack", [False, True])
def test_assembled_derivatives_equal_the_whole_programs(with_slip, with_slack):
    derivs, x, f, g = program(with_slip, with_slack)
    lam_f = ca.SX.sym("lam_f")
    lam_g = ca.SX.sym("lam_g", g.numel())
    ref = ca.Function(
        "ref", [x, lam_f, lam_g],
        [f, g, ca.jacobian(g, x), ca.triu(ca.hessian(lam_f * f + ca.dot(lam_g, g), x)[0])],
    )  # fmt: skip
    f_fn = ca.Function("f", [derivs.x], [derivs.f])
    rng = np.random.default_rng(1)
    p = ca.DM.zeros(0, 1)
    for _ in range(5):
        xv = rng.normal(size=x.numel())
        lf = float(rng.uniform(0.2, 2.0))
        lg = rng.normal(size=g.numel())
        f_r, g_r, J_r, H_r = (np.asarray(ca.DM(v)) for v in ref(xv, lf, lg))
        g_a, J_a = (np.asarray(ca.DM(v)) for v in derivs.jac_g(xv, p))
        H_a = np.asarray(ca.DM(derivs.hess_lag(xv, p, lf, lg)))
        assert float(f_fn(xv)) == pytest.approx(f_r.item(), rel=1e-12)
        np.testing.assert_allclose(g_a, g_r, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(J_a, J_r, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(H_a, H_r, rtol=1e-11, atol=1e-12)
        assert np.all(np.tril(H_a, -1) == 0.0)  # IPOPT's upper triangle


def test_jacobian_matches_central_differences():
    derivs, x, _, _ = program(with_slip=True, with_slack=True, seed=3)
    p = ca.DM.zeros(0, 1)
    xv = np.random.default_rng(4).normal(size=x.numel())
    _, J = (np.asarray(ca.DM(v)) for v in derivs.jac_g(xv, p))
    h = 1e-6
    for j in range(xv.size):
        e = np.zeros_like(xv)
        e[j] = h
        fd = (np.asarray(ca.DM(derivs.jac_g(xv + e, p)[0])) - np.asarray(ca.DM(derivs.jac_g(xv - e, p)[0]))) / (2 * h)
        np.testing.assert_allclose(J[:, j : j + 1], fd, rtol=1e-6, atol=1e-8)


def test_rows_that_are_not_affine_in_the_placeholders_are_refused():
    """A row the assembly cannot express (a product of two knots' rows) fails loudly, not silently."""
    kr = knot_rows()
    Y = ca.SX.sym("Y", NV, K)
    Z = ca.SX.sym("Z", 3, K)
    g = ca.vertcat(Z[0, 0] * Z[0, 1], Z[1, 2])
    with pytest.raises(RuntimeError):
        _PathDerivatives(Y, None, Z, ca.SX(0, K), kr, None, np.zeros(NV), g, ca.sumsqr(Y))
