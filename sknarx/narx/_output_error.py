"""Output-error kernels: the free run with its exact parameter sensitivities.

A polynomial NARX model ``y(t) = sum_m theta_m p_m(y(t-1..ny), u(t-1..nu))`` run freely
feeds its own outputs back, so the derivative of the simulated output with respect
to a coefficient follows the same recursion (the sensitivity equation):

    s_j(t) = p_j(z(t)) + sum_i (d f / d yhat(t-i)) s_j(t-i),

with ``z(t)`` the lagged simulated outputs and measured inputs. The compiled kernel
returns the free run and the ``(N, m)`` sensitivity matrix in one pass, so a
Gauss-Newton / Levenberg-Marquardt step on the simulation error costs one free run
and a small least-squares solve (Ljung, *System Identification*, 2nd ed., sec. 10.3;
Piroddi & Spinelli, Int. J. Control 76(17), 2003, for simulation-error criteria on
polynomial NARX models).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .freerun import free_run, term_factors

__all__ = ["OutputErrorFit", "free_run_sensitivities", "refine_output_error",
           "simulation_error"]


@njit(cache=True, nogil=True)
def _free_run_sens(u, y, theta, factors, ny, nu, start, bound, S):  # pragma: no cover
    n = u.shape[0]
    m = factors.shape[0]
    depth = factors.shape[1]
    lagv = np.empty(ny + nu)
    g = np.empty(max(ny, 1))
    for t in range(start, n):
        for i in range(ny):
            lagv[i] = y[t - 1 - i]
        for i in range(nu):
            lagv[ny + i] = u[t - 1 - i]
        for i in range(ny):
            g[i] = 0.0
        acc = 0.0
        for k in range(m):
            p = 1.0
            for d in range(depth):
                j = factors[k, d]
                if j < 0:
                    break
                p *= lagv[j]
            S[t, k] = p
            acc += theta[k] * p
            # d p_k / d z_j: one factor left out at a time (repeated factors count twice)
            for d in range(depth):
                j = factors[k, d]
                if j < 0:
                    break
                if j >= ny:
                    continue
                q = theta[k]
                for e in range(depth):
                    jj = factors[k, e]
                    if jj < 0:
                        break
                    if e != d:
                        q *= lagv[jj]
                g[j] += q
        y[t] = acc
        if not (abs(acc) <= bound):
            return t
        for i in range(ny):
            gi = g[i]
            if gi != 0.0:
                for k in range(m):
                    S[t, k] += gi * S[t - 1 - i, k]
    return -1


def free_run_sensitivities(u, y0, theta, exponents, ny, nu, bound=np.inf):
    """Free run from ``y0`` and its sensitivities to the coefficients.

    Parameters
    ----------
    u : ndarray (N,)
    y0 : ndarray
        The first ``max(ny, nu)`` outputs (measured: the run's initial conditions).
    theta : ndarray (m,)
    exponents : ndarray (m, ny + nu)
    bound : float
        ``|y|`` above it is a divergence.

    Returns
    -------
    y : ndarray (N,)
    S : ndarray (N, m)
        ``d y(t) / d theta``; zero over the initial conditions.
    diverged_at : int
        The sample where ``|y|`` left the bound, or -1.
    """
    u = np.ascontiguousarray(u, dtype=float)
    start = max(ny, nu)
    y = np.zeros(u.shape[0])
    y[:start] = np.asarray(y0, dtype=float)[:start]
    theta = np.ascontiguousarray(theta, dtype=float)
    S = np.zeros((u.shape[0], theta.shape[0]))
    at = _free_run_sens(u, y, theta, term_factors(exponents), ny, nu, start, float(bound), S)
    return y, S, int(at)


def simulation_error(records, theta, exponents, ny, nu, bound=np.inf, skip=0):
    """Sum of squared free-run errors over ``records`` (``(u, y)`` pairs), each run from
    its own measured initial outputs, counted from sample ``max(ny, nu) + skip``;
    ``inf`` when a run diverges."""
    start = max(ny, nu)
    theta = np.atleast_2d(theta)
    sse = 0.0
    for u, y in records:
        yh, at = free_run(u, theta, exponents, ny, nu, y0=y[:start], bound=bound)
        if at >= 0:
            return np.inf
        e = y[start + skip:] - yh[start + skip:]
        sse += float(e @ e)
    return sse if np.isfinite(sse) else np.inf


@dataclass
class OutputErrorFit:
    """Result of :func:`refine_output_error`."""

    theta: np.ndarray  # (m,)
    cov: np.ndarray  # (m, m): sigma2 (J^T J)^-1 at the optimum
    sigma2: float  # simulation-error variance
    dof: int  # residual degrees of freedom
    sse: float  # final sum of squared simulation errors
    sse_start: float  # at the starting coefficients
    n_iter: int
    converged: bool


def _stack(records, theta, exponents, ny, nu, bound, skip):
    start = max(ny, nu) + skip
    es, Ss = [], []
    for u, y in records:
        yh, S, at = free_run_sensitivities(u, y, theta, exponents, ny, nu, bound)
        if at >= 0:
            return None, None
        es.append(y[start:] - yh[start:])
        Ss.append(S[start:])
    e = np.concatenate(es)
    if not np.all(np.isfinite(e)):
        return None, None
    return e, np.vstack(Ss)


def refine_output_error(records, theta0, exponents, ny, nu, bound=np.inf, skip=0,
                        max_iter=50, rtol=1e-7):
    """Minimise the free-run error of ``records`` over the coefficients
    (Levenberg-Marquardt with exact sensitivities).

    Steps that make a run diverge are rejected like any step that raises the error,
    so the result is never worse than ``theta0``. Convergence: the relative decrease
    of the error below ``rtol`` at an accepted step.
    """
    theta = np.asarray(theta0, dtype=float).copy()
    e, J = _stack(records, theta, exponents, ny, nu, bound, skip)
    if e is None:
        raise FloatingPointError("the starting model's free run diverges")
    sse0 = sse = float(e @ e)
    lam = 1e-3
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 -- reported
        A = J.T @ J
        b = J.T @ e
        d = np.sqrt(np.clip(np.diag(A), 1e-300, None))
        accepted = False
        while lam < 1e12:
            M = A / np.outer(d, d) + lam * np.eye(len(theta))
            step = np.linalg.solve(M, b / d) / d
            cand = theta + step
            e_new, J_new = _stack(records, cand, exponents, ny, nu, bound, skip)
            sse_new = float(e_new @ e_new) if e_new is not None else np.inf
            if sse_new < sse:
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            converged = True  # no descent direction left at this precision
            break
        gain = (sse - sse_new) / sse
        theta, e, J, sse = cand, e_new, J_new, sse_new
        lam = max(lam / 10.0, 1e-12)
        if gain < rtol:
            converged = True
            break
    m = len(theta)
    dof = max(len(e) - m, 1)
    sigma2 = sse / dof
    A = J.T @ J
    try:
        cov = sigma2 * np.linalg.inv(A)
    except np.linalg.LinAlgError:
        cov = sigma2 * np.linalg.pinv(A)
    return OutputErrorFit(theta=theta, cov=cov, sigma2=sigma2, dof=dof, sse=sse,
                          sse_start=sse0, n_iter=it, converged=converged)
