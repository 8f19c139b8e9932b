"""Free-run (model predicted output) simulation of a polynomial NARX model.

The recursion ``y(t) = sum_m theta_m(t) * term_m(y(t-1..), u(t-1..))`` is
inherently sequential, so it is compiled with numba: 81,921 samples with ten
terms take about a millisecond.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["FreeRunDivergenceError", "term_factors", "free_run", "free_run_mimo"]


class FreeRunDivergenceError(RuntimeError):
    """The free-running model left the bounded region (it is unstable there)."""


def term_factors(exponents: np.ndarray) -> np.ndarray:
    """Each term as a padded list of lagged-variable indices (repeated per power)."""
    exponents = np.asarray(exponents, dtype=np.int64)
    depth = int(exponents.sum(axis=1).max()) if exponents.size else 0
    out = -np.ones((exponents.shape[0], max(depth, 1)), dtype=np.int64)
    for i, row in enumerate(exponents):
        idx = [j for j, p in enumerate(row) for _ in range(int(p))]
        out[i, : len(idx)] = idx
    return out


@njit(cache=True, nogil=True)
def _free_run(u, y, theta, factors, ny, nu, start, bound):  # pragma: no cover - compiled
    n = u.shape[0]
    s = factors.shape[0]
    depth = factors.shape[1]
    lagv = np.empty(ny + nu)
    constant = theta.shape[0] == 1
    for t in range(start, n):
        for i in range(ny):
            lagv[i] = y[t - 1 - i]
        for i in range(nu):
            lagv[ny + i] = u[t - 1 - i]
        row = 0 if constant else t
        acc = 0.0
        for m in range(s):
            v = theta[row, m]
            for d in range(depth):
                j = factors[m, d]
                if j < 0:
                    break
                v *= lagv[j]
            acc += v
        y[t] = acc
        if not (abs(acc) <= bound):
            return t
    return -1


def free_run(u, theta, exponents, ny, nu, y0=None, bound=np.inf):
    """Simulate from the input alone.

    Parameters
    ----------
    u : ndarray (N,)
    theta : ndarray (N, s) or (1, s)
        Coefficients per sample (a run-up) or constant.
    exponents : ndarray (s, ny + nu)
    y0 : ndarray or None
        The first ``max(ny, nu)`` outputs (initial conditions); zeros by default.
    bound : float
        Divergence is declared when ``|y|`` exceeds it.

    Returns
    -------
    y : ndarray (N,)
        NaN from the divergence point on, if any.
    diverged_at : int
        Sample index of divergence, or -1.
    """
    u = np.ascontiguousarray(u, dtype=float)
    start = max(ny, nu)
    y = np.zeros(u.shape[0])
    if y0 is not None:
        y0 = np.asarray(y0, dtype=float).reshape(-1)
        if y0.shape[0] < start:
            raise ValueError(
                f"y0 needs the first {start} outputs (max lag); got {y0.shape[0]}."
            )
        y[:start] = y0[:start]
    theta = np.ascontiguousarray(np.atleast_2d(theta), dtype=float)
    at = _free_run(u, y, theta, term_factors(exponents), ny, nu, start, float(bound))
    if at >= 0:
        y[at:] = np.nan
    return y, int(at)


@njit(cache=True, nogil=True)
def _free_run_mimo(U, Y, theta, factors, owner, ny, nu, start, bound):  # pragma: no cover
    n, p = Y.shape
    q = U.shape[1]
    s = factors.shape[0]
    depth = factors.shape[1]
    lagv = np.empty(p * ny + q * nu)
    acc = np.empty(p)
    constant = theta.shape[0] == 1
    for t in range(start, n):
        for c in range(p):
            for i in range(ny):
                lagv[c * ny + i] = Y[t - 1 - i, c]
        for c in range(q):
            for i in range(nu):
                lagv[p * ny + c * nu + i] = U[t - 1 - i, c]
        row = 0 if constant else t
        for c in range(p):
            acc[c] = 0.0
        for m in range(s):
            v = theta[row, m]
            for d in range(depth):
                j = factors[m, d]
                if j < 0:
                    break
                v *= lagv[j]
            acc[owner[m]] += v
        for c in range(p):
            Y[t, c] = acc[c]
            if not (abs(acc[c]) <= bound[c]):
                return t
    return -1


def free_run_mimo(U, thetas, exponents, owner, ny, nu, n_outputs, Y0=None, bound=None):
    """Joint free run of a multi-output model: every output from the inputs and the
    outputs' own simulated lags.

    Parameters
    ----------
    U : ndarray (N, n_inputs)
    thetas : ndarray (N, s) or (1, s)
        Coefficients of all outputs' terms, side by side.
    exponents : ndarray (s, n_outputs * ny + n_inputs * nu)
    owner : ndarray (s,)
        The output each term belongs to.
    Y0 : ndarray (max_lag, n_outputs) or None
        Initial outputs; zeros by default.
    bound : ndarray (n_outputs,) or None
        Divergence is declared when an output's ``|y|`` exceeds its bound.

    Returns
    -------
    Y : ndarray (N, n_outputs)
        NaN from the divergence point on, if any.
    diverged_at : int
    """
    U = np.ascontiguousarray(np.asarray(U, dtype=float).reshape(len(U), -1))
    start = max(ny, nu)
    Y = np.zeros((U.shape[0], n_outputs))
    if Y0 is not None:
        Y0 = np.asarray(Y0, dtype=float).reshape(-1, n_outputs)
        if Y0.shape[0] < start:
            raise ValueError(f"Y0 needs the first {start} outputs (max lag) of each output; "
                             f"got {Y0.shape[0]}.")
        Y[:start] = Y0[:start]
    theta = np.ascontiguousarray(np.atleast_2d(thetas), dtype=float)
    bound = (np.full(n_outputs, np.inf) if bound is None
             else np.broadcast_to(np.asarray(bound, dtype=float), (n_outputs,)).copy())
    at = _free_run_mimo(U, Y, theta, term_factors(exponents),
                        np.asarray(owner, dtype=np.int64), ny, nu, start, bound)
    if at >= 0:
        Y[at:] = np.nan
    return Y, int(at)
