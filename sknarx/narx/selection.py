"""CommonStructureEFOR: one term set common to all speeds (AERR-based EFOR)."""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from ._design import as_configured_output, check_nan_rows, read_term_matrix
from ._orthogonal import compress, condition_numbers, efor, matrix_blocks, unscale
from ._simulation_selection import select_by_simulation
from .terms import parse_terms, split_noise_terms

__all__ = ["CommonStructureEFOR", "IllConditionedWarning", "fit_efor"]

#: Warn when the coefficients' expected relative round-off error exceeds this: about
#: ``eps * cond^2`` for the Gram solver (it squares the condition number of the
#: column-normalised selected regressors), ``eps * cond`` for TSQR. At the paper's
#: settings (cond ~1e5) the Gram error is ~2e-6, harmless; at 10 kHz (cond ~1e9) it
#: is of order one.
ROUNDOFF_WARN = 1e-4
EPS = float(np.finfo(float).eps)


class IllConditionedWarning(UserWarning):
    """The selected regressors are nearly collinear (often: oversampled data)."""


def prune_terms(Z, norms, res, esr, tol):
    """Backward elimination after the forward pass.

    Greedy forward selection can admit a term early that later ones make
    redundant (e.g. ``u(t-2)`` standing in for ``y(t-1)`` until ``y(t-1)`` itself is
    chosen). Repeatedly drop the term whose removal leaves the lowest ESR, as long
    as the smaller model still meets the ESR threshold; then refit in the original
    order. The ESR of a term set does not depend on the order of its terms.
    """
    selected = list(res.selected)
    M = Z.shape[2] - 1
    while len(selected) > 1:
        best, best_esr = None, np.inf
        for j in selected:
            rest = [i for i in selected if i != j]
            sub = Z[:, :, rest + [M]]
            try:
                r = efor(sub, norms[:, rest + [M]], order=range(len(rest)), tol=tol)
            except np.linalg.LinAlgError:
                continue
            if r.esr < best_esr:
                best, best_esr = j, r.esr
        if best is None or not best_esr < esr:
            break
        selected.remove(best)
    if len(selected) == len(res.selected):
        return res
    out = efor(Z, norms, order=selected, tol=tol)
    out.stop_reason = res.stop_reason + "+pruned"
    return out


def fit_efor(Z, norms, esr, max_terms, tol, order=None, prune=False):
    """Run the kernel and derive the reported quantities (shared with the regressor)."""
    res = efor(Z, norms, esr=esr, max_terms=max_terms, order=order, tol=tol)
    if prune and order is None and esr is not None:
        res = prune_terms(Z, norms, res, esr, tol)
    if not res.selected:
        raise ValueError(
            "No term could be selected: every candidate is linearly dependent or zero in at "
            "least one dataset. Check that the input excites the system (it must not be "
            "constant or zero)."
        )
    coef = unscale(res.coef, norms, res.selected)
    cond = condition_numbers(Z, res.selected)
    return res, coef, cond


def roundoff_error(cond, solver: str):
    """Expected relative round-off error of the coefficients for a condition number."""
    cond = np.asarray(cond, dtype=float)
    return EPS * cond**2 if solver == "gram" else EPS * cond


def warn_conditioning(cond, speeds=None, solver="gram"):
    """Warn when round-off may corrupt the coefficients (see ``ROUNDOFF_WARN``)."""
    worst = int(np.argmax(cond))
    error = float(roundoff_error(cond[worst], solver))
    if error > ROUNDOFF_WARN:
        where = f" at speed {speeds[worst]:g} rad/s" if speeds is not None else ""
        fix = ("use solver='qr', lower the sampling rate (decimate) or use fewer lags"
               if solver == "gram" else "lower the sampling rate (decimate) or use fewer lags")
        warnings.warn(
            f"The selected regressors are ill-conditioned (condition number "
            f"{cond[worst]:.3g}{where}): round-off may change the coefficients by about "
            f"{100 * min(error, 1.0):.2g} %. The data are probably oversampled: {fix}.",
            IllConditionedWarning,
            stacklevel=3,
        )


class CommonStructureEFOR(TransformerMixin, BaseEstimator):
    """Select one NARX term set common to K datasets by AERR-based EFOR.

    At each step every remaining candidate is orthogonalised, in every dataset,
    against the terms already chosen; its error reduction ratio ``ERR_k`` is
    computed per dataset and averaged into ``AERR = 100/K sum_k ERR_k``; the
    candidate with the largest AERR is selected for all datasets. Selection stops
    when the error-to-signal ratio ``ESR = 100 - sum AERR`` drops below ``esr``
    or after ``max_terms`` terms. With one dataset this is the classical FROLS
    algorithm of Billings et al.

    Parameters
    ----------
    esr : float, default=0.01
        Stop threshold on the error-to-signal ratio, in percent.
    max_terms : int or None, default=None
        Largest number of terms to select.
    solver : {'gram', 'qr'}, default='gram'
        How each dataset is compressed in one chunked pass: ``'gram'`` (fastest)
        or ``'qr'`` (TSQR; about 4x slower, keeps accuracy on badly conditioned,
        oversampled data).
    tol : float, default=1e-12
        Relative squared norm below which an orthogonalised candidate counts as
        linearly dependent on the selected terms.
    prune : bool, default=True
        After the forward pass, drop terms that the model does not need to meet
        the ``esr`` threshold (backward elimination). Greedy forward selection can
        pick a proxy term early (e.g. ``u(t-2)`` for ``y(t-1)``) that later terms make
        redundant; pruning removes it. ``prune=False`` is the paper's method
        exactly (and classical FROLS for one dataset).
    selection : {'one_step', 'simulation'}, default='one_step'
        ``'simulation'`` chooses the terms by their free-run error pooled over every
        dataset, as :class:`SpeedScheduledNarx` does with the same option (Piroddi &
        Spinelli 2003); the columns must be NARX terms with an ``u(t-1)`` column
        (as :class:`NarxTermDictionary` makes them), from which the input is read;
        noise columns ``e(t-k)`` are not candidates then. ``aerr_`` and ``err_`` are
        reported for the chosen terms in their order.
    simulation_tol : float, default=0.002
        See :class:`SpeedScheduledNarx`.
    n_jobs : int or None, default=None
        Parallel candidate evaluations of ``selection='simulation'`` (joblib threads).

    Attributes
    ----------
    selected_indices_ : ndarray of int
        Column indices of the selected terms, in selection order.
    selected_terms_ : list of str
        Their names.
    aerr_ : ndarray of shape (n_selected,)
        AERR of each step, percent.
    esr_ : float
        Final error-to-signal ratio, percent.
    err_ : DataFrame of shape (n_datasets, n_selected)
        Per-dataset ERR (fraction) of each selected term; index = speed.
    coef_ : DataFrame of shape (n_datasets, n_selected)
        Per-dataset coefficients of the selected terms (inverse Gram-Schmidt).
    speeds_ : ndarray or None
        Speed of each dataset (rad/s), when the input carried speeds.
    condition_number_ : float
        Largest condition number of the normalised selected regressors.
    stop_reason_ : str

    Examples
    --------
    >>> import numpy as np
    >>> from sknarx import NarxTermDictionary, CommonStructureEFOR
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(400); y = np.zeros(400)
    >>> for t in range(2, 400):
    ...     y[t] = 0.5 * y[t - 1] + u[t - 1] + 0.1 * u[t - 2] ** 2
    >>> P = NarxTermDictionary(ny=2, nu=2, degree=2).fit_transform(np.column_stack([u, y]))
    >>> sel = CommonStructureEFOR(esr=1e-8, max_terms=3).fit(P, y)
    >>> sorted(sel.selected_terms_)
    ['u(t-1)', 'u(t-2)^2', 'y(t-1)']
    """

    _parameter_constraints = {
        "esr": [Interval(Real, 0, 100, closed="both")],
        "max_terms": [Interval(Integral, 1, None, closed="left"), None],
        "solver": [StrOptions({"gram", "qr"})],
        "tol": [Interval(Real, 0, 1, closed="left")],
        "prune": ["boolean"],
        "selection": [StrOptions({"one_step", "simulation"})],
        "simulation_tol": [Interval(Real, 0, 1, closed="left")],
        "n_jobs": [Integral, None],
    }

    def __init__(self, esr=0.01, max_terms=None, solver="gram", tol=1e-12, prune=True,
                 selection="one_step", simulation_tol=0.002, n_jobs=None):
        self.esr = esr
        self.max_terms = max_terms
        self.solver = solver
        self.tol = tol
        self.prune = prune
        self.selection = selection
        self.simulation_tol = simulation_tol
        self.n_jobs = n_jobs

    def fit(self, X, y):
        """Select the common terms.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_candidates)
            Candidate terms, e.g. from :class:`NarxTermDictionary`; an index named
            ``speed`` splits the rows into datasets (runs of equal speed).
        y : array-like of shape (n_samples,)
            Output.

        Returns
        -------
        self : CommonStructureEFOR
        """
        self._validate_params()
        tm = read_term_matrix(self, X, y, "CommonStructureEFOR")
        Z, norms = compress_groups(tm, self.solver)
        res, coef, cond = fit_efor(Z, norms, self.esr, self.max_terms, self.tol, prune=self.prune)
        if self.selection == "simulation":
            chosen = _simulation_structure(tm, Z, norms, res.selected, self.max_terms,
                                           self.simulation_tol, self.n_jobs)
            res, coef, cond = fit_efor(Z, norms, None, None, self.tol, order=chosen)
        speeds = tm.dataset_speeds()
        warn_conditioning(cond, speeds, self.solver)
        names = [tm.names[j] for j in res.selected]
        index = pd.Index(speeds, name="speed") if speeds is not None else None
        self.selected_indices_ = np.asarray(res.selected, dtype=int)
        self.selected_terms_ = names
        self.aerr_ = res.aerr
        self.esr_ = float(res.esr)
        self.err_ = pd.DataFrame(res.err, columns=names, index=index)
        self.coef_ = pd.DataFrame(coef, columns=names, index=index)
        self.speeds_ = speeds
        self.condition_number_ = float(np.max(cond))
        self.stop_reason_ = res.stop_reason
        return self

    def transform(self, X):
        """Keep the selected columns, in selection order (the index is kept).

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, n_candidates)

        Returns
        -------
        X_selected : DataFrame or ndarray of shape (n_samples, n_selected)
        """
        check_is_fitted(self, "selected_indices_")
        arr = check_nan_rows(validate_data(self, X, reset=False, ensure_all_finite="allow-nan",
                                           dtype=np.float64))
        if isinstance(X, pd.DataFrame):
            return as_configured_output(self, X.iloc[:, self.selected_indices_])
        return arr[:, self.selected_indices_]

    def get_support(self, indices=False):
        """Mask (or indices, in selection order) of the selected candidates."""
        check_is_fitted(self, "selected_indices_")
        if indices:
            return self.selected_indices_.copy()
        mask = np.zeros(self.n_features_in_, dtype=bool)
        mask[self.selected_indices_] = True
        return mask

    def get_feature_names_out(self, input_features=None):
        """Names of the selected terms in selection order."""
        check_is_fitted(self, "selected_indices_")
        return np.asarray(self.selected_terms_, dtype=object)


def _simulation_structure(tm, Z, norms, one_step, max_terms, tol, n_jobs):
    """Columns of the term matrix ``tm`` chosen by pooled free-run error; the input is
    read back from its ``u(t-1)`` column."""
    process = split_noise_terms(tm.names)[0]
    try:
        exponents, ny, nu = parse_terms([tm.names[j] for j in process])
    except ValueError as exc:
        raise ValueError(
            "selection='simulation' free-runs the candidates, so the columns must be NARX "
            f"terms as NarxTermDictionary names them ({exc})") from None
    if "u(t-1)" not in tm.names:
        raise ValueError(
            "selection='simulation' reads the input from the 'u(t-1)' column, which X "
            "lacks; build the candidates with NarxTermDictionary(nu >= 1, degree >= 1).")
    col = tm.P[:, tm.names.index("u(t-1)")]
    records, scale = [], 0.0
    for a, b in tm.groups:
        u = np.zeros(b - a)
        u[:-1] = np.nan_to_num(col[a + 1:b])  # u(t-1) at row t + 1 is u(t)
        records.append([(u, tm.y[a:b])])
        scale = max(scale, float(np.nanmax(np.abs(tm.y[a:b]))))
    cols = list(process) + [Z.shape[1] - 1]  # the candidates and the output
    Zs = Z[:, :, cols]
    Gn = np.einsum("kij,kil->kjl", Zs, Zs)
    where = {j: i for i, j in enumerate(process)}
    seed = [where[j] for j in one_step if j in where]
    budget = max_terms if max_terms is not None else min(len(process), 30)
    result = select_by_simulation(records, Gn, norms[:, cols], exponents, ny, nu, budget,
                                  tol=tol, bound=1e3 * scale if scale > 0 else np.inf,
                                  n_jobs=n_jobs, seeds=[seed])
    if not result.selected:
        raise ValueError(
            "selection='simulation' found no term whose model free-runs better than zero "
            "output; check that the input drives the output, or use selection='one_step'.")
    return [process[i] for i in result.selected]


def compress_groups(tm, solver):
    """Stacked normalised factors of every dataset of a term matrix."""
    Zs, norms = [], []
    width = tm.P.shape[1] + 1
    for k, (a, b) in enumerate(tm.groups):
        ok = tm.valid_rows(a, b)
        P, yk = tm.P[a:b][ok], tm.y[a:b][ok]
        if P.shape[0] < 2:
            raise ValueError(
                f"Dataset {k} has n_samples = {P.shape[0]} usable sample(s) (rows with a "
                "complete lag history); at least 2 are needed."
            )
        if not np.any(yk):
            raise ValueError(
                f"The output of dataset {k} is identically zero; nothing can be identified."
            )
        Z, nrm = compress(matrix_blocks(P, yk), width, solver)
        Zs.append(Z)
        norms.append(nrm)
    return np.stack(Zs), np.stack(norms)
