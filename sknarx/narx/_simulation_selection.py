"""Structure selection by simulation error, with pruning.

One-step-ahead error reduction (FROLS, EFOR) judges a term by how well it predicts
one sample ahead from *measured* lags; on real data that admits terms that make the
free run wrong or unstable. Piroddi & Spinelli (An identification algorithm for
polynomial NARX models based on simulation error minimization, Int. J. Control 76(17),
2003) judge a term by the free run instead:

0. the search starts from the best-simulating of the given seeds (by default the linear
   model over every lag; the estimator adds the one-step selection's structure): an
   oscillator needs its output lags together, and added one at a time none of them
   helps the free run. With no seed that free-runs, it starts from nothing;
1. each step adds the candidate term whose model (coefficients by least squares on the
   one-step regression, as there) has the smallest simulation error;
2. after each addition, terms whose removal raises the simulation error by less than
   the stated share are pruned, one at a time, the least useful first (a term must
   keep earning what it took to be added);
3. the search stops when no addition lowers the error by the stated share, or at the
   term budget.

With several speeds the structure is common: every candidate set is fitted per speed
and judged by the simulation error pooled over all records and speeds (each speed's
squared free-run error over its output energy, averaged), so no selected structure
diverges on its own training records. The least-squares solves use each speed's
normalised Gram matrix of the full dictionary, made once by the compressors
(:mod:`._orthogonal`); a candidate costs one free run per record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from joblib import Parallel, delayed

from .freerun import free_run, free_run_mimo

__all__ = ["SimulationSelection", "select_by_simulation", "select_joint_by_simulation"]

#: a pooled relative simulation error at round-off: the records are reproduced exactly
_EXACT = 1e3 * np.finfo(float).eps


@dataclass
class SimulationSelection:
    """Result of :func:`select_by_simulation`."""

    selected: list  # dictionary columns, in the order kept
    coef: np.ndarray  # (K, m): per-speed least-squares coefficients of the kept set
    error: float  # pooled relative simulation error of the kept set
    history: list  # (action, column, error) of every accepted addition and pruning


def ls_coef(Gn, norms, cols):
    """Per speed, the least-squares coefficients of the dictionary columns ``cols`` in
    raw units, from the normalised Gram matrices ``Gn`` (K, M+1, M+1; last: the output)
    and their column norms; ``None`` when the columns are linearly dependent."""
    cols = list(cols)
    K, M1 = norms.shape
    out = np.zeros((K, len(cols)))
    for k in range(K):
        A = Gn[k][np.ix_(cols, cols)]
        b = Gn[k][cols, M1 - 1]
        try:
            c = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            return None
        if np.linalg.cond(A) > 1e12:  # linearly dependent on the set: no new term
            return None
        safe = np.where(norms[k, cols] > 0, norms[k, cols], 1.0)
        out[k] = c * norms[k, M1 - 1] / safe
    return out


class _Judge:
    """Fits a column set per speed and scores its pooled free-run error."""

    def __init__(self, groups, Gn, norms, exponents, ny, nu, bound):
        self.groups = groups  # per speed: list of (u, y) records
        self.Gn = Gn  # (K, M+1, M+1): normalised Gram of [P, y]
        self.norms = norms  # (K, M+1)
        self.exponents = exponents
        self.ny, self.nu = ny, nu
        self.start = max(ny, nu)
        self.bound = bound
        self.energy = [sum(float(y[self.start:] @ y[self.start:]) for _, y in g)
                       for g in groups]

    def coef(self, cols):
        return ls_coef(self.Gn, self.norms, cols)

    def error(self, cols):
        """Pooled relative simulation error of ``cols``; ``inf`` when a run diverges."""
        if not cols:
            return 1.0
        coef = self.coef(cols)
        if coef is None:
            return np.inf
        ex = self.exponents[list(cols)]
        total = 0.0
        for k, records in enumerate(self.groups):
            sse = 0.0
            for u, y in records:
                yh, at = free_run(u, coef[k][None], ex, self.ny, self.nu,
                                  y0=y[:self.start], bound=self.bound)
                if at >= 0:
                    return np.inf
                e = y[self.start:] - yh[self.start:]
                sse += float(e @ e)
            total += sse / self.energy[k]
        value = total / len(self.groups)
        return value if np.isfinite(value) else np.inf


def select_by_simulation(groups, Gn, norms, exponents, ny, nu, max_terms, tol=0.01,
                         bound=np.inf, n_jobs=None, progress=None, seeds=()):
    """Choose a common term set by simulation error (see the module docstring).

    Parameters
    ----------
    groups : list of list of (u, y)
        The records of each speed.
    Gn, norms : ndarray
        Per speed, the normalised Gram matrix of ``[P, y]`` over the full dictionary and
        its column norms (as the compressors make them).
    exponents : ndarray (M, ny + nu)
        The dictionary's terms.
    max_terms : int
    tol : float
        Stop when the best addition lowers the pooled simulation error by less than this
        share of it.
    n_jobs : int or None
        Candidates are judged in parallel through joblib (threads: the free run is
        compiled and releases the GIL).
    progress : callable or None
        Called with the number of terms after each accepted step.
    seeds : sequence of lists of columns
        Further starting sets besides the linear model; the best-simulating one
        starts the search.
    """
    judge = _Judge(groups, Gn, norms, np.asarray(exponents), ny, nu, bound)
    M = Gn.shape[1] - 1
    ex = np.asarray(exponents)
    usable = [j for j in range(M) if norms[:, j].min() > 0]
    linear = [j for j in usable if ex[j].sum() == 1]
    chosen, current, history = _search(judge, usable, [linear, *seeds],
                                       lambda chosen, j: len(chosen) < max_terms,
                                       max_terms, tol, n_jobs, progress)
    coef = judge.coef(chosen) if chosen else np.zeros((Gn.shape[0], 0))
    return SimulationSelection(selected=chosen, coef=coef, error=current, history=history)


def _search(judge, items, seeds, can_add, budget, tol, n_jobs, progress):
    """The greedy search with pruning over ``items`` (see the module docstring)."""
    chosen: list = []
    current = 1.0
    for seed in seeds:
        seed = [j for j in seed if can_add([], j)][:budget]
        err = judge.error(seed) if seed else np.inf
        if err < current:
            chosen, current = seed, float(err)
    history = [("start", j, current) for j in chosen]
    parallel = Parallel(n_jobs=n_jobs, prefer="threads")

    def prune(candidates):
        nonlocal current
        while len(chosen) > 1:
            trial = parallel(delayed(judge.error)([c for c in chosen if c != j])
                             for j in candidates())
            worst = int(np.argmin(trial))
            if trial[worst] > max(current * (1.0 + tol), _EXACT):
                break
            removed = candidates()[worst]
            chosen.remove(removed)
            current = float(trial[worst])
            history.append(("prune", removed, current))

    for _ in range(4 * budget):  # each addition lowers the error by tol: a safe cap
        pool = [j for j in items if j not in chosen and can_add(chosen, j)]
        if not pool:
            break
        errs = parallel(delayed(judge.error)(chosen + [j]) for j in pool)
        best = int(np.argmin(errs))
        if (not np.isfinite(errs[best]) or errs[best] > current * (1.0 - tol)
                or current <= _EXACT):
            break
        chosen.append(pool[best])
        current = float(errs[best])
        history.append(("add", pool[best], current))
        if len(chosen) > 2:  # prune: a term the free run does not need goes
            prune(lambda: chosen[:-1])
        if progress is not None:
            progress(len(chosen))
    prune(lambda: list(chosen))  # the seed's terms the free run does not need go too
    return chosen, current, history


class _JointJudge:
    """Fits each output's columns per speed and scores the joint free run's pooled error
    (items are ``(output, column)`` pairs)."""

    def __init__(self, groups, Gn, norms, exponents, ny, nu, n_outputs, bound):
        self.Gn, self.norms = Gn, norms  # per output: (K, M+1, M+1), (K, M+1)
        self.groups = groups  # per speed: list of (U, Y) records
        self.exponents = exponents
        self.ny, self.nu, self.p = ny, nu, n_outputs
        self.start = max(ny, nu)
        self.bound = bound
        self.energy = [np.sum([np.sum(Y[self.start:] ** 2, axis=0) for _, Y in g], axis=0)
                       for g in groups]

    def split(self, items):
        return [[j for c, j in items if c == o] for o in range(self.p)]

    def error(self, items):
        cols = self.split(items)  # an output without terms simulates as zero
        if not items:
            return 1.0
        coefs = [ls_coef(self.Gn[o], self.norms[o], c) if c
                 else np.zeros((len(self.groups), 0)) for o, c in enumerate(cols)]
        if any(c is None for c in coefs):
            return np.inf
        ex = self.exponents[[j for c in cols for j in c]]
        owner = np.array([o for o, c in enumerate(cols) for _ in c], dtype=np.int64)
        total = 0.0
        for k, records in enumerate(self.groups):
            theta = np.concatenate([c[k] for c in coefs])[None]
            sse = 0.0
            for U, Y in records:
                Ys, at = free_run_mimo(U, theta, ex, owner, self.ny, self.nu, self.p,
                                       Y0=Y[:self.start], bound=self.bound)
                if at >= 0:
                    return np.inf
                sse = sse + np.sum((Y[self.start:] - Ys[self.start:]) ** 2, axis=0)
            total += float(np.mean(sse / self.energy[k]))
        value = total / len(self.groups)
        return value if np.isfinite(value) else np.inf


def select_joint_by_simulation(groups, Gn, norms, exponents, ny, nu, n_outputs, max_terms,
                               tol=0.01, bound=np.inf, n_jobs=None, seeds=()):
    """One term set per output by the joint free run's simulation error, pooled over
    outputs (each over its own energy), records and speeds.

    ``Gn[c]``, ``norms[c]``: output ``c``'s normalised Gram matrices of ``[P, y_c]`` per
    speed; ``seeds``: further starting sets, each a list of columns per output. Returns
    the columns chosen for each output.
    """
    judge = _JointJudge(groups, Gn, norms, np.asarray(exponents), ny, nu, n_outputs, bound)
    M = Gn.shape[2] - 1
    ex = np.asarray(exponents)
    items = [(c, j) for c in range(n_outputs) for j in range(M) if norms[c][:, j].min() > 0]
    linear = [(c, j) for c, j in items if ex[j].sum() == 1]
    seed_items = [[(c, j) for c in range(n_outputs)
                   for j in [j for o, j in linear if o == c][:max_terms]]]
    seed_items += [[(c, j) for c, cols in enumerate(seed) for j in list(cols)[:max_terms]]
                   for seed in seeds]

    def can_add(chosen, item):
        return sum(1 for c, _ in chosen if c == item[0]) < max_terms

    chosen, _, _ = _search(judge, items, seed_items, can_add, n_outputs * max_terms, tol,
                           n_jobs, None)
    return judge.split(chosen)
