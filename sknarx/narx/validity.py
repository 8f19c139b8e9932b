"""Model validity tests: correlations of the one-step residuals (Billings & Voon 1986).

A NARX/NARMAX model is adequate when its one-step-ahead residuals ``e(t)`` are
unpredictable from past residuals and inputs, linearly and nonlinearly. Billings &
Voon (1986) and Billings & Zhu (1994) test that with five normalised correlation
functions; each must stay inside the 95 % band ``+-1.96/sqrt(N)`` for all lags:

==============  =====================================  ========================================
test            correlation                            a violation points to
==============  =====================================  ========================================
``phi_ee``      ``e(t-tau)`` with ``e(t)``, tau >= 1   coloured noise: add noise terms
                                                       (``noise_lags``) or output lags
``phi_ue``      ``u(t-tau)`` with ``e(t)``             missing linear input terms or lags
``phi_e_eu``    ``e(t-1-tau) u(t-1-tau)`` with         missing cross (input x noise/output)
                ``e(t)``, tau >= 0                     terms
``phi_u2_e``    ``u^2(t-tau)'`` with ``e(t)``          missing even-order input nonlinearity
``phi_u2_e2``   ``u^2(t-tau)'`` with ``e^2(t)'``       missing input-dependent terms in the
                                                       residual's power (nonlinearity or
                                                       input-dependent noise)
==============  =====================================  ========================================

(``'`` means the mean removed.) Per speed each record is tested alone; ``pooled``
sums the cross-products of all records before normalising, a test with
``sum_k N_k`` samples.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.signal import lfilter
from scipy.stats import binom, norm

from .sweep_data import as_datasets, read_sample_table
from .terms import TermSet, split_noise_terms

__all__ = ["one_step_residuals", "correlation_tests", "validity_summary", "TESTS"]

#: The five tests, in the order of Billings & Voon.
TESTS = ("phi_ee", "phi_ue", "phi_e_eu", "phi_u2_e", "phi_u2_e2")


def _final_step(model):
    return model[-1] if hasattr(model, "steps") else model


def one_step_residuals(model, u, y, omega) -> np.ndarray:
    """One-step-ahead prediction errors of a fitted model on one record.

    ``e(t) = y(t) - sum_m theta_m(omega) p_m(t)`` for ``t >= max lag``; for a NARMAX
    model the noise terms use the errors themselves (the predictor's recursion
    ``e = (y - P theta_process) / C(q)``).

    Parameters
    ----------
    model : SpeedScheduledNarx or Pipeline ending in one
    u, y : array-like (n_samples,)
    omega : float
        Speed of the record, rad/s.

    Returns
    -------
    e : ndarray (n_samples - max_lag,)
    """
    model = _final_step(model)
    if model.exponents_ is None:
        raise ValueError("The model's terms are not NARX terms; residuals cannot be formed.")
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    lag = max(model.ny_, model.nu_)
    if y.size <= lag + 1:
        raise ValueError(f"A record of {y.size} samples is too short for lags up to {lag}.")
    theta = np.asarray(model.coefficients_at(float(omega)), dtype=float)
    process, noise, lags = split_noise_terms(model.selected_terms_)
    P = TermSet(model.exponents_, model.ny_, model.nu_).evaluate(u, y, lag, y.size)
    r = y[lag:] - P @ theta[process]
    if not noise:
        return r
    a = np.zeros(max(lags) + 1)
    a[0] = 1.0
    for i, lg in zip(noise, lags, strict=True):
        a[lg] += theta[i]
    return lfilter([1.0], a, r)


def _records(X, speeds):
    if isinstance(X, pd.DataFrame):
        datasets, _ = read_sample_table(X)
        return datasets
    return as_datasets(X, speeds)


def _xcorr(A, b, taus):
    """``sum_t A[i, t - tau] b(t)`` for each row ``i`` of ``A`` and each tau (centred series).

    The rows that share ``b`` go through one matrix-vector product per lag.
    """
    n = b.size
    out = np.empty((A.shape[0], len(taus)))
    for j, tau in enumerate(taus):
        if tau >= 0:
            out[:, j] = A[:, : n - tau] @ b[tau:]
        else:
            out[:, j] = A[:, -tau:] @ b[: n + tau]
    return out


def _record_sums(u, e, max_lag):
    """Cross-product sums and energies of the five tests on one record's aligned u and e.

    Returns ``{test: (lags, numerator, sum a^2, sum b^2)}``.
    """
    ec = e - e.mean()
    uc = u - u.mean()
    u2 = u**2 - np.mean(u**2)
    e2 = e**2 - np.mean(e**2)
    eu = e * u
    eu = eu - eu.mean()
    sym = np.arange(-max_lag, max_lag + 1)
    pos = np.arange(0, max_lag + 1)
    A = np.stack([uc, u2, eu, ec])  # everything correlated with e(t)
    energy = np.einsum("ij,ij->i", A, A)
    lags_all = np.arange(-max_lag, max_lag + 2)
    num = _xcorr(A, ec, lags_all)  # one pass for the four tests against e(t)
    at = max_lag  # column of lag 0 in num
    ee2 = float(ec @ ec)
    return {
        "phi_ee": (pos[1:], num[3, at + pos[1:]], energy[3], ee2),
        "phi_ue": (sym, num[0, at + sym], energy[0], ee2),
        # e(t-1-tau) u(t-1-tau) with e(t): the eu series at lag tau + 1
        "phi_e_eu": (pos, num[2, at + pos + 1], energy[2], ee2),
        "phi_u2_e": (sym, num[1, at + sym], energy[1], ee2),
        "phi_u2_e2": (sym, _xcorr(u2[None, :], e2, sym)[0], energy[1], float(e2 @ e2)),
    }


def correlation_tests(model, X, speeds=None, max_lag=20) -> pd.DataFrame:
    """The five Billings-Voon correlation tests, per speed and pooled.

    Parameters
    ----------
    model : SpeedScheduledNarx or Pipeline ending in one
        A fitted model.
    X : list of (u, y) pairs, or long DataFrame (``speed``, ``u``, ``y``)
        The records to test on (the training records, or held-out ones).
    speeds : array-like of shape (n_records,), optional
        Speed of each record (rad/s), with a list of pairs.
    max_lag : int, default=20
        Largest lag ``tau`` (samples).

    Returns
    -------
    table : DataFrame
        One row per scope, test and lag: ``scope`` (``'per_speed'`` or
        ``'pooled'``), ``speed`` (rad/s; NaN when pooled), ``test``, ``lag``
        (samples), ``value`` (normalised correlation), ``band`` (95 % limit
        ``1.96/sqrt(N)``), ``outside`` (``|value| > band``), ``n_samples``.

    Examples
    --------
    >>> import numpy as np
    >>> from sknarx import SpeedScheduledNarx
    >>> from sknarx.narx.validity import correlation_tests, validity_summary
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(-1, 1, 2000); y = np.zeros(2000)
    >>> for t in range(1, 2000):
    ...     y[t] = 0.5 * y[t - 1] + u[t - 1] + 0.01 * rng.standard_normal()
    >>> model = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2).fit([(u, y)], [100.0])
    >>> table = correlation_tests(model, [(u, y)], [100.0], max_lag=10)
    >>> bool(validity_summary(table).query("scope == 'pooled'")["passed"].all())
    True
    """
    fitted = _final_step(model)
    if not (isinstance(max_lag, (int, np.integer)) and max_lag >= 1):
        raise ValueError(f"max_lag must be a positive integer, got {max_lag!r}.")
    lag = max(fitted.ny_, fitted.nu_)
    cols = {k: [] for k in ("scope", "speed", "test", "lag", "value", "band", "n_samples")}
    pooled: dict = {}

    def block(scope, speed, test, taus, value, band, n):
        k = len(taus)
        cols["scope"].append(np.full(k, scope, dtype=object))
        cols["speed"].append(np.full(k, speed))
        cols["test"].append(np.full(k, test, dtype=object))
        cols["lag"].append(np.asarray(taus, dtype=int))
        cols["value"].append(np.asarray(value, dtype=float))
        cols["band"].append(np.full(k, band))
        cols["n_samples"].append(np.full(k, n))

    for d in _records(X, speeds):
        e = one_step_residuals(fitted, d.u, d.y, d.speed)
        u = np.asarray(d.u, dtype=float)[lag:]
        n = e.size
        if n <= 2 * max_lag + 2:
            raise ValueError(
                f"The record at {d.speed:g} rad/s has {n} residuals, too few for lags up to "
                f"{max_lag}; lower max_lag."
            )
        band = 1.96 / np.sqrt(n)
        for test, (taus, num, aa, bb) in _record_sums(u, e, max_lag).items():
            den = np.sqrt(aa * bb)
            value = num / den if den > 0 else np.full(len(taus), np.nan)
            acc = pooled.setdefault(test, [taus, 0.0, 0.0, 0.0, 0])
            acc[1] = acc[1] + num
            acc[2] += aa
            acc[3] += bb
            acc[4] += n
            block("per_speed", float(d.speed), test, taus, value, band, n)
    for test, (taus, num, aa, bb, n) in pooled.items():
        den = np.sqrt(aa * bb)
        value = num / den if den > 0 else np.full(len(taus), np.nan)
        block("pooled", np.nan, test, taus, value, 1.96 / np.sqrt(n), n)
    table = pd.DataFrame({k: np.concatenate(v) for k, v in cols.items()})
    table.insert(6, "outside", np.abs(table["value"].to_numpy()) > table["band"].to_numpy())
    return table


def validity_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Pass/fail of each test from :func:`correlation_tests`.

    About 5 % of the lags of an adequate model fall outside a 95 % band by
    chance, so counting excursions alone would fail good models; and one large
    excursion (a single missing term acts at a single lag) must fail a test
    however few lags it touches. A test therefore fails when either

    * more lags fall outside than the 99.9th percentile of
      ``Binomial(n_lags, 0.05)`` (``allowed``), or
    * the largest ``|value|`` exceeds the band scaled to a family-wise level of
      0.1 % over the lags (Bonferroni: ``z_{1 - 0.0005/n_lags} / 1.96`` bands,
      ``max_ratio``).

    Returns
    -------
    summary : DataFrame
        ``scope``, ``speed``, ``test``, ``n_lags``, ``n_outside``, ``allowed``,
        ``max_abs`` (largest ``|value|/band``), ``max_ratio``, ``passed``.
    """
    rows = []
    for (scope, speed, test), g in table.groupby(["scope", "speed", "test"], dropna=False,
                                                 sort=False):
        n = len(g)
        allowed = int(binom.ppf(0.999, n, 0.05))
        max_ratio = float(norm.ppf(1 - 0.0005 / n) / 1.96)
        n_out = int(g["outside"].sum())
        max_abs = float(np.max(np.abs(g["value"]) / g["band"]))
        rows.append({"scope": scope, "speed": speed, "test": test, "n_lags": n,
                     "n_outside": n_out, "allowed": allowed, "max_abs": max_abs,
                     "max_ratio": max_ratio,
                     "passed": bool(n_out <= allowed and max_abs <= max_ratio)})
    return pd.DataFrame(rows)
