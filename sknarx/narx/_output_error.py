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
           "refine_speed_functions", "simulation_error"]


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


def _normal_equations(records, theta, exponents, ny, nu, bound, skip, basis=None):
    """Sum of squared free-run errors and the Gauss-Newton normal equations
    ``(J^T J, J^T e)`` accumulated record by record (``J`` never held whole); ``None``
    when a run diverges. With ``basis`` (per record, a vector ``v``) the parameters are
    ``beta`` of ``theta = beta @ v`` (shape ``(m, len(v))``) and the record's
    Jacobian is ``S kron v``."""
    start = max(ny, nu) + skip
    sse, A, g = 0.0, None, None
    for r, (u, y) in enumerate(records):
        th = theta if basis is None else theta @ basis[r]
        yh, S, at = free_run_sensitivities(u, y, th, exponents, ny, nu, bound)
        if at >= 0:
            return None
        e = y[start:] - yh[start:]
        S = S[start:]
        StS, Ste = S.T @ S, S.T @ e
        if basis is not None:
            v = basis[r]
            StS, Ste = np.kron(StS, np.outer(v, v)), np.kron(Ste, v)
        sse += float(e @ e)
        A = StS if A is None else A + StS
        g = Ste if g is None else g + Ste
    if not np.isfinite(sse):
        return None
    return sse, A, g


def _levenberg_marquardt(evaluate, x0, max_iter, rtol):
    """Minimise ``sse(x)`` given ``evaluate(x) -> (sse, J^T J, J^T e)`` or ``None``
    (a divergence, treated as an infinite error). Returns ``(x, sse, A, sse0, n_iter,
    converged)``."""
    x = np.asarray(x0, dtype=float).copy()
    first = evaluate(x)
    if first is None:
        raise FloatingPointError("the starting model's free run diverges")
    sse, A, g = first
    sse0 = sse
    lam = 1e-3
    converged = False
    it = 0
    flat = x.reshape(-1)
    for it in range(1, max_iter + 1):  # noqa: B007 -- reported
        d = np.sqrt(np.clip(np.diag(A), 1e-300, None))
        accepted = None
        while lam < 1e12:
            M = A / np.outer(d, d) + lam * np.eye(flat.size)
            step = np.linalg.solve(M, g / d) / d
            cand = (flat + step).reshape(x.shape)
            trial = evaluate(cand)
            if trial is not None and trial[0] < sse:
                accepted = trial
                break
            lam *= 10.0
        if accepted is None:
            converged = True  # no descent direction left at this precision
            break
        gain = (sse - accepted[0]) / sse
        x, (sse, A, g) = cand, accepted
        flat = x.reshape(-1)
        lam = max(lam / 10.0, 1e-12)
        if gain < rtol:
            converged = True
            break
    return x, sse, A, sse0, it, converged


def _covariance(A, sigma2):
    try:
        return sigma2 * np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return sigma2 * np.linalg.pinv(A)


def refine_output_error(records, theta0, exponents, ny, nu, bound=np.inf, skip=0,
                        max_iter=50, rtol=1e-7):
    """Minimise the free-run error of ``records`` over the coefficients
    (Levenberg-Marquardt with exact sensitivities).

    Steps that make a run diverge are rejected like any step that raises the error,
    so the result is never worse than ``theta0``. Convergence: the relative decrease
    of the error below ``rtol`` at an accepted step.
    """
    theta, sse, A, sse0, it, ok = _levenberg_marquardt(
        lambda th: _normal_equations(records, th, exponents, ny, nu, bound, skip),
        theta0, max_iter, rtol)
    start = max(ny, nu) + skip
    n = sum(len(y) - start for _, y in records)
    dof = max(n - theta.size, 1)
    sigma2 = sse / dof
    return OutputErrorFit(theta=theta, cov=_covariance(A, sigma2), sigma2=sigma2, dof=dof,
                          sse=sse, sse_start=sse0, n_iter=it, converged=ok)


def refine_speed_functions(groups, basis, beta0, exponents, ny, nu, sigma2, bound=np.inf,
                           max_iter=50, rtol=1e-7):
    """Minimise the free-run error of every speed's records over the coefficients of
    the speed functions, ``theta(omega_k) = beta @ basis[k]``.

    Parameters
    ----------
    groups : list of list of (u, y)
        Each speed's records.
    basis : ndarray (K, J + 1)
        The speed basis at each speed (powers of the scaled speed).
    beta0 : ndarray (m, J + 1)
    sigma2 : ndarray (K,)
        Each speed's simulation-error variance: its records are weighted by
        ``1 / sigma2_k``, so the result is the maximum-likelihood fit under independent
        Gaussian output errors and its covariance is ``(J^T W J)^-1``.

    Returns
    -------
    OutputErrorFit
        ``theta`` holds ``beta`` (m, J + 1); ``cov`` is over ``beta.ravel()``.
    """
    records, vs, weights = [], [], []
    for k, group in enumerate(groups):
        for u, y in group:
            records.append((u, y))
            vs.append(basis[k])
            weights.append(1.0 / sigma2[k])

    def evaluate(beta):
        total, A, g = 0.0, 0.0, 0.0
        for r, (u, y) in enumerate(records):
            out = _normal_equations([(u, y)], beta, exponents, ny, nu, bound, 0,
                                    basis=[vs[r]])
            if out is None:
                return None
            sse, Ar, gr = out
            total += weights[r] * sse
            A = A + weights[r] * Ar
            g = g + weights[r] * gr
        return total, A, g

    beta, sse, A, sse0, it, ok = _levenberg_marquardt(evaluate, beta0, max_iter, rtol)
    start = max(ny, nu)
    n = sum(len(y) - start for _, y in records)
    dof = max(n - beta.size, 1)
    # weighted errors have unit variance when the per-speed variances are right
    return OutputErrorFit(theta=beta, cov=_covariance(A, 1.0), sigma2=sse / dof, dof=dof,
                          sse=sse, sse_start=sse0, n_iter=it, converged=ok)
