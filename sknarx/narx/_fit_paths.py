"""The fitting paths of :class:`~sknarx.narx.SpeedScheduledNarx`.

``fit(datasets, speeds)`` (:func:`fit_sweep`: dictionary, common-structure selection by
one-step or free-run error, per-speed coefficients, output-error refinement, NARMAX noise
terms) and ``fit(X, y)`` on a selected term matrix (:func:`fit_terms`) each return a
:class:`_Fit`; the estimator turns it into its fitted attributes. The functions read the
estimator's parameters and write only ``output_scale_``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import chain

import numpy as np
import pandas as pd

from .._progress import phase
from ._design import read_term_matrix
from ._els import extended_least_squares
from ._orthogonal import coef_covariance, compress, termset_blocks
from ._output_error import refine_output_error
from ._simulation_selection import select_by_simulation
from .freerun import FreeRunDivergenceError
from .selection import compress_groups, fit_efor
from .sweep_data import as_datasets, check_series
from .terms import TermSet, monomial_exponents, noise_term_name, split_noise_terms, term_names

__all__ = ["fit_sweep", "fit_terms", "is_sweep"]


@dataclass
class _Fit:
    """What one fitting path hands to ``fit`` (per dataset k, term m)."""

    names: list
    coef: np.ndarray  # (K, m)
    cov: np.ndarray  # (K, m, m)
    sigma2: np.ndarray  # (K,)
    dof: np.ndarray  # (K,)
    err: np.ndarray  # (K, m) fraction
    aerr: np.ndarray  # (m,) percent
    esr: float  # percent
    cond: np.ndarray  # (K,)
    speeds: np.ndarray | None
    n_iter: int = 0
    records: list | None = None  # per speed, its (u, y) records (the direct API only)


def _with_noise_model(fitted: _Fit, els, y_list, process=None, noise_pos=None) -> _Fit:
    """Fold an extended-least-squares result into the fit.

    Without ``process`` (``fit(datasets, speeds)``) the admitted noise terms are
    appended after the process terms; with it (a Pipeline's term matrix) the
    columns keep the order of ``X``: ``process`` and ``noise_pos`` (ascending lag)
    are their positions.
    """
    if not els.noise_lags:  # white equation error: NARX least squares is already right
        fitted.n_iter = els.n_iter
        return fitted
    yy = np.array([float(y @ y) for y in y_list])
    esr = float(100.0 * np.mean(els.sigma2 * els.dof / yy))
    if process is None:
        names = fitted.names + [noise_term_name(lag) for lag in els.noise_lags]
        return _Fit(names=names, coef=els.coef, cov=els.cov, sigma2=els.sigma2, dof=els.dof,
                    err=np.hstack([fitted.err, els.err]),
                    aerr=np.concatenate([fitted.aerr, 100.0 * els.err.mean(axis=0)]),
                    esr=esr, cond=fitted.cond, speeds=fitted.speeds, n_iter=els.n_iter)
    perm = np.asarray(list(process) + list(noise_pos))  # ELS order -> column of X
    coef = np.empty_like(els.coef)
    coef[:, perm] = els.coef
    cov = np.empty_like(els.cov)
    cov[:, perm[:, None], perm[None, :]] = els.cov
    return _Fit(names=fitted.names, coef=coef, cov=cov, sigma2=els.sigma2, dof=els.dof,
                err=fitted.err, aerr=fitted.aerr, esr=esr, cond=fitted.cond,
                speeds=fitted.speeds, n_iter=els.n_iter)


def _n_records(X) -> int:
    """Number of ``(u, y)`` records in the direct API's first argument."""
    if isinstance(X, tuple) and len(X) == 2 and np.ndim(X[0]) == 1:
        return 1
    return len(X)


def _group_by_speed(datasets):
    """``[(speed, [(index, dataset), ...]), ...]`` in order of first appearance."""
    groups: dict = {}
    for k, d in enumerate(datasets):
        groups.setdefault(d.speed, []).append((k, d))
    return list(groups.items())


def is_sweep(X) -> bool:
    """``X`` is a sweep (a long table with ``u``, or ``(u, y)`` records), not a term
    matrix."""
    if isinstance(X, pd.DataFrame):
        return "u" in X.columns
    if isinstance(X, (list, tuple)) and len(X) > 0:
        first = X[0]
        return isinstance(first, (list, tuple)) and len(first) == 2 and np.ndim(first[0]) == 1
    return False



def fit_sweep(est, X, speeds) -> _Fit:
    """``fit(datasets, speeds)``: records grouped by speed, each group compressed in one
    chunked pass over the full dictionary; terms by one-step EFOR or by free-run error;
    least-squares coefficients per speed, then optionally output-error refinement or
    NARMAX noise terms. Without speeds the records are one operating point."""
    no_speeds = speeds is None and not isinstance(X, pd.DataFrame)
    datasets = as_datasets(X, np.zeros(_n_records(X)) if no_speeds else speeds)
    groups = _group_by_speed(datasets)  # records of one speed share coefficients
    ws = None if no_speeds else np.array([w for w, _ in groups])
    if ws is not None:
        est._check_speeds(ws)
    if est.refine == "output_error" and est.noise_lags > 0:
        raise ValueError(
            "refine='output_error' fits the free run, which has no noise terms; set "
            "noise_lags=0 (or refine=None for a NARMAX model).")
    lag = max(est.ny, est.nu)
    termset = TermSet(monomial_exponents(est.ny, est.nu, est.degree), est.ny, est.nu)
    names_all = term_names(termset.exponents, est.ny, est.nu)
    width = len(names_all) + 1
    Zs, norms, records, scale = [], [], [], 0.0
    for _, members in groups:
        checked = []
        for k, d in members:
            where = (f"Record {k}" if no_speeds
                     else f"Dataset {k} (speed {d.speed:g} rad/s)")
            u, yk = check_series(d.u, d.y, None if no_speeds else d.speed, lag + 2, where)
            if est.nu > 0 and est.degree > 0 and np.ptp(u) == 0:
                raise ValueError(
                    f"{where}: the input u is constant ({u[0]:g}), so the input terms "
                    "are collinear with the constant and the regression is singular. "
                    "Use a record where the input varies (e.g. the unbalance force "
                    "m e w^2 cos wt).")
            if not np.any(yk[lag:]):
                raise ValueError(f"{where}: the output y is identically zero.")
            checked.append((u, yk))
            scale = max(scale, float(np.max(np.abs(yk))))
        Z, nrm = compress(chain.from_iterable(termset_blocks(termset, u, yk, lag)
                                              for u, yk in checked), width, est.solver)
        Zs.append(Z)
        norms.append(nrm)
        records.append(checked)
    est.output_scale_ = scale
    Z = np.stack(Zs)
    norms = np.stack(norms)
    if est.selection == "simulation":
        one_step = fit_efor(Z, norms, est.esr, est.max_terms, est.tol,
                            prune=est.prune)[0].selected
        chosen = select_by_simulation_of(est, records, Z, norms, termset, [one_step])
        res, coef, cond = fit_efor(Z, norms, None, None, est.tol, order=chosen)
    else:
        res, coef, cond = fit_efor(Z, norms, est.esr, est.max_terms, est.tol,
                                   prune=est.prune)
    n_rows = [sum(len(yk) - lag for _, yk in g) for g in records]
    cov, sigma2, dof = coef_covariance(res, norms, n_rows)
    fitted = _Fit(names=[names_all[j] for j in res.selected], coef=coef, cov=cov,
                  sigma2=sigma2, dof=dof, err=res.err, aerr=res.aerr, esr=res.esr,
                  cond=cond, speeds=ws)
    if est.refine == "output_error":
        refine_per_speed(est, fitted, records, termset.exponents[res.selected])
        fitted.records = records
    if est.noise_lags > 0:
        chosen = TermSet(termset.exponents[res.selected], est.ny, est.nu)
        P_list = [np.vstack([chosen.evaluate(u, yk, lag, len(yk)) for u, yk in g])
                  for g in records]
        y_list = [np.concatenate([yk[lag:] for _, yk in g]) for g in records]
        els = extended_least_squares(P_list, y_list, coef, est.noise_lags)
        fitted = _with_noise_model(fitted, els, y_list)
    return fitted


def select_by_simulation_of(est, records, Z, norms, termset, seeds):
    """Dictionary columns chosen by pooled free-run error (see
    :mod:`sknarx.narx._simulation_selection`)."""
    M = termset.exponents.shape[0]
    budget = est.max_terms if est.max_terms is not None else min(M, 30)
    Gn = np.einsum("kij,kil->kjl", Z, Z)
    with phase("simulation-error selection") as bar:
        result = select_by_simulation(
            records, Gn, norms, termset.exponents, est.ny, est.nu, budget,
            tol=est.simulation_tol, bound=est._bound(), n_jobs=est.n_jobs,
            progress=lambda n: bar.set_postfix_str(f"{n} terms"), seeds=seeds)
    if not result.selected:
        raise ValueError(
            "selection='simulation' found no term whose model free-runs better than "
            "zero output on the training records; check that the input drives the "
            "output, or use selection='one_step'.")
    return result.selected


def refine_per_speed(est, fitted: _Fit, records, exponents):
    """Per speed, the coefficients that minimise the free-run error of its records
    (exact sensitivities), with their output-error covariance."""
    with phase("output-error refinement") as bar:
        for k, group in enumerate(records):
            try:
                oe = refine_output_error(group, fitted.coef[k], exponents, est.ny,
                                         est.nu, bound=est._bound())
            except FloatingPointError:
                where = ("" if fitted.speeds is None
                         else f" at {fitted.speeds[k]:g} rad/s")
                raise FreeRunDivergenceError(
                    f"refine='output_error': the selected model's free run diverges on "
                    f"its own training records{where}, so there is no simulation error "
                    "to refine from; use selection='simulation' (it never keeps such a "
                    "structure), fewer terms or a lower term degree.") from None
            fitted.coef[k] = oe.theta
            fitted.cov[k] = oe.cov
            fitted.sigma2[k] = oe.sigma2
            fitted.dof[k] = oe.dof
            fitted.n_iter = max(fitted.n_iter, oe.n_iter)
            bar.set_postfix_str(f"{k + 1}/{len(records)} speed(s)")


def fit_terms(est, X, y) -> _Fit:
    """``fit(X, y)`` in a Pipeline: the given term columns, in their order, per dataset
    of the ``speed`` index; noise columns are iterated by extended least squares."""
    tm = read_term_matrix(est, X, y, "SpeedScheduledNarx")
    speeds = tm.dataset_speeds()
    if speeds is not None:
        est._check_speeds(speeds)
    Z, norms = compress_groups(tm, est.solver)
    try:
        res, coef, cond = fit_efor(Z, norms, None, None, est.tol,
                                   order=range(tm.P.shape[1]))
    except np.linalg.LinAlgError as exc:
        raise ValueError(
            f"SpeedScheduledNarx: the given terms are linearly dependent ({exc}); "
            "drop the redundant columns."
        ) from exc
    ok = ~np.all(np.isnan(tm.P), axis=1)
    est.output_scale_ = float(np.max(np.abs(tm.y[ok])))
    n_rows = [int(tm.valid_rows(a, b).sum()) for a, b in tm.groups]
    cov, sigma2, dof = coef_covariance(res, norms, n_rows)
    fitted = _Fit(names=list(tm.names), coef=coef, cov=cov, sigma2=sigma2, dof=dof,
                  err=res.err, aerr=res.aerr, esr=res.esr, cond=cond, speeds=speeds)
    process, noise, lags = split_noise_terms(tm.names)
    if noise:
        # The dictionary's noise columns hold first-stage innovation estimates: iterate
        # them into prediction errors of this model (extended least squares).
        rows = [tm.valid_rows(a, b) for a, b in tm.groups]
        P_list = [tm.P[a:b][r][:, process] for (a, b), r in zip(tm.groups, rows,
                                                                 strict=True)]
        y_list = [tm.y[a:b][r] for (a, b), r in zip(tm.groups, rows, strict=True)]
        order = np.argsort(lags)
        els = extended_least_squares(P_list, y_list, coef[:, process], max(lags),
                                     select=False, candidates=[lags[i] for i in order])
        fitted = _with_noise_model(fitted, els, y_list, process,
                                   [noise[i] for i in order])
    return fitted
