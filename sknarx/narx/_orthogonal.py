"""Private kernels of the orthogonal-regression stages.

Two *compressors* reduce each dataset's regression ``[P_k, y_k]`` (N x (M+1)) to a
small factor ``Z_k`` ((M+1) x (M+1)) with the same inner products, in one chunked
pass that never holds all K x N x M regressors in memory:

* ``gram``: accumulate the Gram matrix chunk by chunk (one SYRK per chunk, the
  cheapest possible pass), normalise it and take a symmetric square root;
* ``qr``: a chunked (TSQR) R factor; about four times the flops but it does not
  square the condition number, for badly oversampled data.

Columns are scaled to unit norm before factorisation, so the selection does not
depend on the physical scale of u and y (displacements of 1e-5 m have cubes of
1e-15; no absolute tolerance appears anywhere).

One *greedy kernel* then runs the paper's AERR-based extended forward orthogonal
regression (modified Gram-Schmidt) on the stacked factors of all datasets at once.
With K = 1 it is the classical FROLS algorithm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.linalg.blas import dsyrk as syrk
from threadpoolctl import threadpool_limits

CHUNK_ROWS = 16384


class _GramAccumulator:
    def __init__(self, width):
        self.G = np.zeros((width, width), order="F")

    def add(self, block):
        # BLAS syrk on a column-major block: half the flops of a general product, no copy.
        self.G = syrk(1.0, np.asfortranarray(block), beta=1.0, c=self.G, trans=1, lower=0,
                      overwrite_c=True)

    def finish(self):
        G = np.triu(self.G) + np.triu(self.G, 1).T
        norms = np.sqrt(np.clip(np.diag(G), 0.0, None))
        safe = np.where(norms > 0, norms, 1.0)
        Gn = G / safe[:, None] / safe[None, :]
        lam, V = np.linalg.eigh(Gn)
        Z = (np.sqrt(np.clip(lam, 0.0, None))[:, None]) * V.T
        return Z, norms


class _QRAccumulator:
    def __init__(self, width):
        self.R = np.zeros((0, width))

    def add(self, block):
        stacked = np.vstack([self.R, block])
        self.R = sla.qr(stacked, mode="r", overwrite_a=True, check_finite=False)[0]
        self.R = self.R[: min(self.R.shape)]

    def finish(self):
        R = self.R
        width = R.shape[1]
        if R.shape[0] < width:
            R = np.vstack([R, np.zeros((width - R.shape[0], width))])
        norms = np.sqrt((R**2).sum(axis=0))
        safe = np.where(norms > 0, norms, 1.0)
        return R / safe[None, :], norms


def compress(blocks, width: int, solver: str = "gram", blas_threads: int | None = 1):
    """Factor ``Z`` (width x width) with ``Z.T @ Z`` the normalised Gram of the stacked
    blocks, plus the column norms. ``blocks`` yields row blocks of ``[P, y]``."""
    if solver == "gram":
        acc = _GramAccumulator(width)
    elif solver == "qr":
        acc = _QRAccumulator(width)
    else:
        raise ValueError(f"solver must be 'gram' or 'qr', got {solver!r}.")
    with threadpool_limits(limits=blas_threads, user_api="blas"):
        for block in blocks:
            acc.add(block)
        return acc.finish()


def termset_blocks(termset, u, y, start: int, chunk: int = CHUNK_ROWS):
    """Row blocks of ``[P, y]`` for samples ``start..N-1``, built on the fly."""
    n = len(y)
    width = termset.exponents.shape[0] + 1
    buf = np.empty((min(chunk, max(n - start, 0)), width), order="F")
    for a in range(start, n, chunk):
        b = min(a + chunk, n)
        block = buf[: b - a]
        termset.evaluate(u, y, a, b, out=block[:, :-1])
        block[:, -1] = y[a:b]
        yield block


def matrix_blocks(P, y, chunk: int = CHUNK_ROWS):
    """Row blocks of ``[P, y]`` from an in-memory regressor matrix (same chunking)."""
    for a in range(0, len(y), chunk):
        b = min(a + chunk, len(y))
        block = np.empty((b - a, P.shape[1] + 1), order="F")
        block[:, :-1] = P[a:b]
        block[:, -1] = y[a:b]
        yield block


@dataclass
class EforResult:
    """What the greedy kernel found (indices refer to the candidate columns)."""

    selected: list[int]
    aerr: np.ndarray  # (s,) percent, per step
    err: np.ndarray  # (K, s) per-dataset ERR, fraction
    coef: np.ndarray  # (K, s) coefficients of the normalised terms, selection order
    esr: float  # percent
    degenerate: np.ndarray  # (K, M) bool: candidates linearly dependent at the end
    stop_reason: str
    # (K, s, s) unit upper-triangular Gram-Schmidt factors and (K, s) squared norms of
    # the orthogonalised selected terms: what the coefficient covariance needs (it is
    # only formed for the final fit, not in every pruning trial)
    gs_factor: np.ndarray = None
    gs_norms: np.ndarray = None
    # (K,): squared residual norm of the normalised output after the selected terms
    rss: np.ndarray = None


def efor(Z, norms, esr=None, max_terms=None, order=None, tol=1e-12) -> EforResult:
    """AERR-based extended forward orthogonal regression on stacked factors.

    Parameters
    ----------
    Z : ndarray (K, r, M + 1)
        Normalised factors; the last column is the output.
    norms : ndarray (K, M + 1)
        Column norms removed by the normalisation.
    esr : float or None
        Stop when ``100 - sum(AERR) < esr`` (percent).
    max_terms : int or None
    order : sequence of int or None
        Force this term order instead of selecting (used to refit given terms).
    tol : float
        A candidate whose orthogonalised squared norm falls below ``tol`` (relative:
        the columns have unit norm) in any dataset is linearly dependent on the
        selected terms and is never selected.
    """
    Z = np.array(Z, dtype=float, copy=True)
    K, _, width = Z.shape
    M = width - 1
    dead_col = norms[:, :M] <= 0
    alive = np.ones(M, dtype=bool)
    limit = M if max_terms is None else min(int(max_terms), M)
    if order is not None:
        limit = len(order)
    selected, aerr_steps, err_steps, proj, ww_steps = [], [], [], [], []
    cum = 0.0
    stop_reason = "max_terms"
    for step in range(limit):
        W = Z[:, :, :M]
        wy = np.einsum("krm,kr->km", W, Z[:, :, M])
        ww = np.einsum("krm,krm->km", W, W)
        degenerate = (ww < tol) | dead_col
        err = np.where(degenerate, 0.0, wy**2 / np.where(degenerate, 1.0, ww))
        aerr = 100.0 * err.mean(axis=0)
        usable = alive & ~degenerate.any(axis=0)
        if order is not None:
            j = int(order[step])
            if not usable[j]:
                raise np.linalg.LinAlgError(
                    f"term {j} is linearly dependent on the earlier terms in at least one "
                    "dataset; the regression is singular"
                )
        else:
            if not usable.any():
                stop_reason = "no independent candidate left"
                break
            j = int(np.argmax(np.where(usable, aerr, -np.inf)))
        selected.append(j)
        aerr_steps.append(aerr[j])
        err_steps.append(err[:, j])
        ww_steps.append(ww[:, j])
        cum += aerr[j]
        alive[j] = False
        # Modified Gram-Schmidt step: project every column (and y) off w_j.
        wj = Z[:, :, j]
        c = np.einsum("kr,krm->km", wj, Z) / ww[:, j][:, None]
        Z -= c[:, None, :] * wj[:, :, None]
        proj.append(c)
        if order is None and esr is not None and 100.0 - cum < esr:
            stop_reason = "esr"
            break
    else:
        stop_reason = "max_terms" if order is None else "forced"
    s = len(selected)
    proj = np.stack(proj, axis=1) if s else np.zeros((K, 0, width))
    coef = np.zeros((K, s))
    factors = np.zeros((K, s, s))
    ww_sel = np.stack(ww_steps, axis=1) if s else np.zeros((K, 0))
    for k in range(K):
        A = np.eye(s)
        for i in range(s):
            A[i, i + 1 :] = proj[k, i, selected[i + 1 :]]
        g = proj[k, :, M]
        coef[k] = inverse_gram_schmidt(A, g)
        factors[k] = A
    W = Z[:, :, :M]
    final_degenerate = (np.einsum("krm,krm->km", W, W) < tol) | dead_col
    return EforResult(
        selected=selected,
        aerr=np.asarray(aerr_steps),
        err=np.stack(err_steps, axis=1) if s else np.zeros((K, 0)),
        coef=coef,
        esr=100.0 - cum,
        degenerate=final_degenerate,
        stop_reason=stop_reason,
        gs_factor=factors,
        gs_norms=ww_sel,
        rss=np.einsum("kr,kr->k", Z[:, :, M], Z[:, :, M]),
    )


def _inverse_gram(A: np.ndarray, ww: np.ndarray) -> np.ndarray:
    """``(P^T P)^-1`` of the selected terms from their Gram-Schmidt factors.

    ``P = W A`` with ``W`` orthogonal columns of squared norms ``ww``, so
    ``(P^T P)^-1 = A^-1 diag(1/ww) A^-T``: the covariance that inverse
    Gram-Schmidt (Eq. 17) propagates from the orthogonal coefficients, whose
    variances are ``sigma^2 / ww``. No Gram matrix is inverted.
    """
    s = len(ww)
    if s == 0:
        return np.zeros((0, 0))
    Ainv = sla.solve_triangular(A, np.eye(s), unit_diagonal=True, check_finite=False)
    return (Ainv / ww[None, :]) @ Ainv.T


def inverse_gram_schmidt(A: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Coefficients of the original terms from orthogonal ones (paper, Eq. 17).

    ``A`` is the unit upper-triangular matrix with ``a[m, i] = <p_i, w_m>/<w_m, w_m>``
    and ``g`` the orthogonal coefficients; back-substitution from the last term.
    """
    s = len(g)
    theta = np.zeros(s)
    for m in range(s - 1, -1, -1):
        theta[m] = g[m] - A[m, m + 1 :] @ theta[m + 1 :]
    return theta


def unscale(coef, norms, selected):
    """Coefficients of the raw terms from those of unit-norm terms, per dataset."""
    sel = np.asarray(selected, dtype=int)
    return coef * norms[:, -1][:, None] / np.where(norms[:, sel] > 0, norms[:, sel], 1.0)


def coef_covariance(res: EforResult, norms: np.ndarray, n_rows) -> tuple[np.ndarray, ...]:
    """Covariance of the raw-term coefficients of every dataset (least-squares theory).

    Parameters
    ----------
    res : EforResult
    norms : ndarray (K, M + 1)
        Column norms removed by the normalisation (last: the output).
    n_rows : array-like (K,)
        Regression rows (samples with a complete history) of each dataset.

    Returns
    -------
    cov : ndarray (K, s, s)
        ``sigma_k^2 (P_k^T P_k)^-1`` in the units of the raw coefficients, with
        ``sigma_k^2 = RSS_k / (N_k - s)`` the one-step residual variance; NaN where
        ``N_k <= s``.
    sigma2 : ndarray (K,)
        Residual variance in output units squared.
    dof : ndarray (K,)
        ``N_k - s``.
    """
    sel = np.asarray(res.selected, dtype=int)
    s = sel.size
    n_rows = np.asarray(n_rows, dtype=float)
    dof = n_rows - s
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma2_n = np.where(dof > 0, res.rss / np.where(dof > 0, dof, 1.0), np.nan)
    scale = norms[:, -1][:, None] / np.where(norms[:, sel] > 0, norms[:, sel], 1.0)
    gram_inv = np.stack([_inverse_gram(A, ww) for A, ww in zip(res.gs_factor, res.gs_norms,
                                                                strict=True)])
    cov = sigma2_n[:, None, None] * gram_inv * scale[:, :, None] * scale[:, None, :]
    return cov, sigma2_n * norms[:, -1] ** 2, dof


def condition_numbers(Z, selected) -> np.ndarray:
    """Condition number (2-norm) of each dataset's column-normalised selected regressors."""
    sel = np.asarray(selected, dtype=int)
    out = np.empty(Z.shape[0])
    for k in range(Z.shape[0]):
        sv = np.linalg.svd(Z[k][:, sel], compute_uv=False)
        out[k] = np.inf if sv[-1] <= 0 else sv[0] / sv[-1]
    return out
