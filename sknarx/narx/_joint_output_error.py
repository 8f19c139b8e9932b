"""Output-error kernels of a multi-output model: the joint free run's sensitivities.

Every output's equation reads the simulated lags of every output, so a coefficient of
one output's equation moves all outputs after one step. With ``S[t, c, k]`` the
derivative of output ``c`` at sample ``t`` with respect to coefficient ``k`` (whose
equation is output ``owner[k]``):

    S[t, c, k] = [owner[k] == c] p_k(z(t)) + sum_{c', i} (d f_c / d y_c'(t-i)) S[t-i, c', k].

One compiled pass gives the joint free run and all of ``S``; the Levenberg-Marquardt
steps of :mod:`._output_error` then minimise the free-run error of all outputs at once,
each weighted by the inverse of its variance.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._output_error import OutputErrorFit, _covariance, _levenberg_marquardt
from .freerun import term_factors

__all__ = ["refine_joint_output_error"]


@njit(cache=True, nogil=True)
def _joint_sens(U, Y, theta, factors, owner, ny, nu, start, S):  # pragma: no cover
    n, p = Y.shape
    q = U.shape[1]
    m = factors.shape[0]
    depth = factors.shape[1]
    nv = p * ny + q * nu
    lagv = np.empty(nv)
    g = np.zeros((p, p * ny))  # d f_c / d (output lag variable)
    acc = np.empty(p)
    for t in range(start, n):
        for c in range(p):
            for i in range(ny):
                lagv[c * ny + i] = Y[t - 1 - i, c]
        for c in range(q):
            for i in range(nu):
                lagv[p * ny + c * nu + i] = U[t - 1 - i, c]
        for c in range(p):
            acc[c] = 0.0
            for j in range(p * ny):
                g[c, j] = 0.0
        for k in range(m):
            c = owner[k]
            v = 1.0
            for d in range(depth):
                j = factors[k, d]
                if j < 0:
                    break
                v *= lagv[j]
            S[t, c, k] = v
            acc[c] += theta[k] * v
            for d in range(depth):
                j = factors[k, d]
                if j < 0:
                    break
                if j >= p * ny:
                    continue
                w = theta[k]
                for e in range(depth):
                    jj = factors[k, e]
                    if jj < 0:
                        break
                    if e != d:
                        w *= lagv[jj]
                g[c, j] += w
        for c in range(p):
            Y[t, c] = acc[c]
            if not np.isfinite(acc[c]):
                return t
        for c in range(p):
            for j in range(p * ny):
                gj = g[c, j]
                if gj != 0.0:
                    cc = j // ny
                    lag = j % ny + 1
                    for k in range(m):
                        S[t, c, k] += gj * S[t - lag, cc, k]
    return -1


def _normal_equations(records, theta, exponents, owner, ny, nu, weights, bound,
                      basis=None):
    """Weighted squared joint free-run error and its Gauss-Newton normal equations,
    record by record; ``None`` on a divergence. ``basis`` as in
    :func:`._output_error._normal_equations` (per record a vector ``v``, parameters
    ``beta`` with ``theta = beta @ v``)."""
    factors = term_factors(exponents)
    owner = np.asarray(owner, dtype=np.int64)
    start = max(ny, nu)
    total, A, gvec = 0.0, None, None
    for r, (U, Y) in enumerate(records):
        th = theta if basis is None else theta @ basis[r]
        Ys = np.zeros_like(Y)
        Ys[:start] = Y[:start]
        S = np.zeros((len(Y), Y.shape[1], th.shape[0]))
        at = _joint_sens(np.ascontiguousarray(U), Ys, np.ascontiguousarray(th, dtype=float),
                         factors, owner, ny, nu, start, S)
        if at >= 0 or np.any(np.abs(Ys) > bound):
            return None
        for c in range(Y.shape[1]):
            e = Y[start:, c] - Ys[start:, c]
            Sc = S[start:, c, :]
            StS, Ste = weights[c] * (Sc.T @ Sc), weights[c] * (Sc.T @ e)
            if basis is not None:
                v = basis[r]
                StS, Ste = np.kron(StS, np.outer(v, v)), np.kron(Ste, v)
            total += weights[c] * float(e @ e)
            A = StS if A is None else A + StS
            gvec = Ste if gvec is None else gvec + Ste
    if not np.isfinite(total):
        return None
    return total, A, gvec


def refine_joint_output_error(records, theta0, exponents, owner, ny, nu, weights,
                              bound=np.inf, basis=None, max_iter=50, rtol=1e-7):
    """Minimise the weighted joint free-run error of ``records`` (``(U, Y)`` pairs)
    over all outputs' coefficients ``theta0`` (side by side), or with ``basis`` over the
    speed-function coefficients ``beta`` (``theta = beta @ basis[r]`` for record ``r``).

    ``weights`` (per output) should be the inverse error variances: the covariance is
    then ``(J^T W J)^-1`` scaled by the weighted residual variance.
    """
    weights = np.asarray(weights, dtype=float)
    bound = np.broadcast_to(np.asarray(bound, dtype=float), (len(weights),))
    x, sse, A, sse0, it, ok = _levenberg_marquardt(
        lambda th: _normal_equations(records, th, exponents, owner, ny, nu, weights, bound,
                                     basis),
        theta0, max_iter, rtol)
    start = max(ny, nu)
    n = sum((len(Y) - start) * Y.shape[1] for _, Y in records)
    dof = max(n - x.size, 1)
    sigma2 = sse / dof  # of the weighted errors: 1 when the weights are right
    return OutputErrorFit(theta=x, cov=_covariance(A, sigma2), sigma2=sigma2, dof=dof,
                          sse=sse, sse_start=sse0, n_iter=it, converged=ok)
