"""Private kernels of NARMAX identification by extended least squares (ELS).

With coloured noise ``y(t) = f(y(t-1..), u(t-1..)) + v(t)``, ``v = H(q) e`` with ``e``
white, lagged outputs in the regressors correlate with the noise and NARX least
squares is biased. ELS (Billings & Zhu; Chen & Billings 1989) adds the lagged
residuals ``e(t-1), ..., e(t-q)`` as regressors (a moving-average noise model),
re-estimates, recomputes the residuals with the new model, and iterates until the
coefficients settle. The residuals then approximate the innovations, the process
coefficients lose their bias, and the noise terms absorb the colour.

Which noise lags enter is decided per iteration by a likelihood-ratio test pooled
over all datasets (forward selection): adding a lag to dataset ``k`` reduces its
residual sum of squares by ``dRSS_k``; under "this lag does not belong"
``sum_k dRSS_k / sigma_k^2`` is chi-square with ``K`` degrees of freedom. A lag is
admitted at the significance ``NOISE_LAG_ALPHA``, chosen strict because a spurious
noise term costs nothing in the free run but would be reported as noise colour.

Every regression works on the R factor of ``[X, y]`` (Householder QR of the
column-scaled data), so sub-models need no new pass over the samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.signal import lfilter
from scipy.stats import chi2

__all__ = ["NOISE_LAG_ALPHA", "lagged", "innovations", "extended_least_squares", "ElsFit"]

#: Significance level of the pooled test that admits a noise lag.
NOISE_LAG_ALPHA = 1e-4


def lagged(e: np.ndarray, lags) -> np.ndarray:
    """Columns ``e(t - l)`` for each lag ``l`` (zeros where ``t - l < 0``)."""
    e = np.asarray(e, dtype=float)
    out = np.zeros((e.size, len(lags)))
    for j, lag in enumerate(lags):
        out[lag:, j] = e[: e.size - lag]
    return out


def innovations(u, y, order: int) -> np.ndarray:
    """First-stage innovation estimate of one record by a long linear ARX.

    Hannan & Rissanen (1982): a linear ARX of high order ``order`` whitens the
    residual well enough to serve as the noise regressors of the first ELS step
    (and of a pipeline's dictionary). Samples without a full history get 0, the
    innovations' expectation.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    n = y.size
    p = int(order)
    out = np.zeros(n)
    if n - p <= 2 * (2 * p + 1):
        return out  # too short for the long model: no colour can be estimated
    cols = [np.ones(n - p)]
    cols += [y[p - i : n - i] for i in range(1, p + 1)]
    cols += [u[p - i : n - i] for i in range(1, p + 1)]
    X = np.column_stack(cols)
    beta, *_ = np.linalg.lstsq(X, y[p:], rcond=None)
    out[p:] = y[p:] - X @ beta
    return out


class _Regression:
    """One dataset's ``[X, y]`` reduced to its (column-scaled) R factor."""

    def __init__(self, X, y):
        A = np.column_stack([X, y])
        self.scale = np.linalg.norm(A, axis=0)
        self.scale[self.scale == 0] = 1.0
        self.R = sla.qr(A / self.scale, mode="r", check_finite=False)[0][: A.shape[1]]
        self.n = A.shape[0]
        self.yy = float((y @ y) / self.scale[-1] ** 2)

    def fit(self, cols):
        """Coefficients, RSS (output units^2) and ``(X^T X)^-1`` of the columns ``cols``."""
        cols = list(cols)
        sub = sla.qr(self.R[:, cols + [self.R.shape[1] - 1]], mode="r", check_finite=False)[0]
        m = len(cols)
        Rx, qy = sub[:m, :m], sub[:m, m]
        rss = float(sub[m, m] ** 2) if sub.shape[0] > m else 0.0
        theta = sla.solve_triangular(Rx, qy, check_finite=False)
        Rinv = sla.solve_triangular(Rx, np.eye(m), check_finite=False)
        sc = self.scale[cols]
        ys = self.scale[-1]
        gram_inv = (Rinv @ Rinv.T) / sc[:, None] / sc[None, :]
        return theta * ys / sc, rss * ys**2, gram_inv


@dataclass
class ElsFit:
    """Result of ELS over K datasets (coefficients ordered process terms, then noise lags)."""

    noise_lags: list  # admitted noise lags, ascending
    coef: np.ndarray  # (K, s + q)
    cov: np.ndarray  # (K, s + q, s + q)
    sigma2: np.ndarray  # (K,) residual variance, output units^2
    dof: np.ndarray  # (K,)
    err: np.ndarray  # (K, q) fraction of output energy removed by each noise lag, in order
    residuals: list  # per dataset, final residuals (regression rows)
    n_iter: int
    converged: bool


def _select(regs, n_process, candidates, fixed):
    """Forward selection of noise lags by the pooled likelihood-ratio test."""
    if fixed is not None:
        return list(fixed)
    chosen: list[int] = []
    K = len(regs)
    while len(chosen) < len(candidates):
        base = [list(range(n_process)) + [n_process + c for c in chosen] for _ in regs]
        rss0 = [reg.fit(b)[1] for reg, b in zip(regs, base, strict=True)]
        best, best_p = None, 1.0
        for c in range(len(candidates)):
            if c in chosen:
                continue
            stat = 0.0
            for reg, b, r0 in zip(regs, base, rss0, strict=True):
                r1 = reg.fit(b + [n_process + c])[1]
                dof = reg.n - len(b) - 1
                if dof <= 0 or r1 <= 0:
                    continue
                stat += (r0 - r1) / (r1 / dof)
            p = float(chi2.sf(stat, K))
            if p < best_p:
                best, best_p = c, p
        if best is None or not best_p < NOISE_LAG_ALPHA:
            break
        chosen.append(best)
    return sorted(chosen)


def _noise_poly(lags, c):
    """``C(q) = 1 + sum_j c_j q^-lag_j`` as lfilter's denominator."""
    a = np.zeros(max(lags, default=0) + 1)
    a[0] = 1.0
    for lag, cj in zip(lags, c, strict=True):
        a[lag] += cj
    return a


def _invertible(a) -> bool:
    return a.size == 1 or bool(np.all(np.abs(np.roots(a)) < 1.0))


def _innovations_of(P, y, theta_p, a):
    """Prediction errors ``eps = (y - P theta_p) / C(q)`` (the one-step residuals)."""
    return lfilter([1.0], a, y - P @ theta_p)


def _gauss_newton(P_list, y_list, coef, lags, max_iter, tol):
    """Prediction-error refinement of the ELS fit; returns coef, cov, sigma2, dof, eps.

    ELS (a pseudo-linear regression) removes the bias but its naive covariance
    ``sigma^2 (X^T X)^-1`` understates the spread: the residual regressors depend on
    the coefficients. Gauss-Newton on the prediction errors uses the gradient
    ``psi = [P, eps(t-lag)] / C(q)``; at the optimum ``sigma^2 (Psi^T Psi)^-1`` is the
    asymptotic covariance of the estimate (Ljung, System Identification, 9.3).
    """
    s = P_list[0].shape[1]
    out_coef, out_cov, sig2, dofs, eps_out = [], [], [], [], []
    for P, y, c in zip(P_list, y_list, coef, strict=True):
        c = np.array(c, dtype=float)
        for _ in range(max_iter):
            a = _noise_poly(lags, c[s:])
            if not _invertible(a):
                break  # a non-invertible noise model has no stable predictor: keep ELS
            eps = _innovations_of(P, y, c[:s], a)
            Psi = lfilter([1.0], a, np.column_stack([P, lagged(eps, lags)]), axis=0)
            step, *_ = np.linalg.lstsq(Psi, eps, rcond=None)
            c = c + step
            if np.max(np.abs(step) / (np.abs(c) + 1e-300)) < tol:
                break
        a = _noise_poly(lags, c[s:])
        if _invertible(a):
            eps = _innovations_of(P, y, c[:s], a)
            Psi = lfilter([1.0], a, np.column_stack([P, lagged(eps, lags)]), axis=0)
        else:  # fall back to the pseudo-linear regressors
            eps = y - P @ c[:s]
            Psi = np.column_stack([P, lagged(eps, lags)])
        dof = y.size - c.size
        sigma2 = float(eps @ eps) / dof if dof > 0 else np.nan
        R = sla.qr(Psi, mode="r", check_finite=False)[0][: c.size]
        Rinv = sla.solve_triangular(R, np.eye(c.size), check_finite=False)
        out_coef.append(c)
        out_cov.append(sigma2 * (Rinv @ Rinv.T))
        sig2.append(sigma2)
        dofs.append(dof)
        eps_out.append(eps)
    return (np.stack(out_coef), np.stack(out_cov), np.array(sig2), np.array(dofs, float),
            eps_out)


def extended_least_squares(P_list, y_list, theta0, noise_lags, e0_list=None, select=True,
                           max_iter=50, tol=1e-8, candidates=None) -> ElsFit:
    """ELS with recursive innovations, then prediction-error (Gauss-Newton) refinement.

    Parameters
    ----------
    P_list, y_list : lists of ndarray
        Per dataset: process regressors (N_k x s) and outputs (N_k,), regression rows only.
    theta0 : ndarray (K, s)
        Starting process coefficients (the NARX least-squares fit).
    noise_lags : int
        Largest noise lag ``q``; candidates are ``e(t-1) .. e(t-q)``.
    e0_list : list of ndarray or None
        Starting residuals; by default ``y - P theta0``.
    select : bool
        Choose the admitted lags by the pooled test (True) or keep all ``q``.
    max_iter, tol : int, float
        Stop when the largest relative change of any coefficient is below ``tol``.
    candidates : list of int or None
        The candidate lags (default ``1 .. noise_lags``).
    """
    K = len(P_list)
    s = P_list[0].shape[1]
    if candidates is None:
        candidates = list(range(1, int(noise_lags) + 1))
    candidates = [int(c) for c in candidates]
    if e0_list is None:
        eps = [y - P @ th for P, y, th in zip(P_list, y_list, theta0, strict=True)]
    else:
        eps = [np.asarray(e, dtype=float) for e in e0_list]
    prev, chosen, converged, it, coef = None, None, False, 0, None
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is reported
        regs = [_Regression(np.column_stack([P, lagged(e, candidates)]), y)
                for P, y, e in zip(P_list, y_list, eps, strict=True)]
        idx = _select(regs, s, candidates, None if select else range(len(candidates)))
        lags = [candidates[c] for c in idx]
        coef = np.stack([reg.fit(list(range(s)) + [s + c for c in idx])[0] for reg in regs])
        new_eps = []
        for P, y, e, c in zip(P_list, y_list, eps, coef, strict=True):
            a = _noise_poly(lags, c[s:])
            if _invertible(a):  # pseudo-linear regression: the recursive innovations
                new_eps.append(_innovations_of(P, y, c[:s], a))
            else:  # posterior residuals stay bounded whatever the noise model
                new_eps.append(y - np.column_stack([P, lagged(e, lags)]) @ c)
        eps = new_eps
        same_set = chosen == idx
        chosen = idx
        if prev is not None and same_set and prev.shape == coef.shape:
            if np.max(np.abs(coef - prev) / (np.abs(coef) + 1e-300)) < tol:
                converged = True
                break
        prev = coef
    coef, cov, sigma2, dof, eps = _gauss_newton(P_list, y_list, coef, lags, max_iter, tol)
    # sequential share of output energy removed by each admitted noise lag
    err = np.zeros((K, len(lags)))
    for k, (P, y, e) in enumerate(zip(P_list, y_list, eps, strict=True)):
        reg = _Regression(np.column_stack([P, lagged(e, lags)]), y)
        yy = float(y @ y)
        last = reg.fit(list(range(s)))[1]
        for j in range(len(lags)):
            now = reg.fit(list(range(s + j + 1)))[1]
            err[k, j] = max(last - now, 0.0) / yy if yy > 0 else 0.0
            last = now
    return ElsFit(noise_lags=lags, coef=coef, cov=cov, sigma2=sigma2, dof=dof, err=err,
                  residuals=eps, n_iter=it, converged=converged)
