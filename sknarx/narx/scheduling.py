"""SpeedScheduledNarx: a common-structure NARX whose coefficients are polynomials in speed."""

from __future__ import annotations

import json
import warnings
from numbers import Integral, Real

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from .._atomic import write_text_atomic
from .._json import json_safe
from ._design import check_nan_rows
from ._fit_paths import _Fit, fit_sweep, fit_terms, is_sweep
from ._intervals import SimulationInterval, simulate_interval
from ._speed_functions import (
    SpeedExtrapolationWarning,
    _spline,
    coefficient_std,
    coefficients_at,
    fit_speed_polynomials,
    refine_speed_functions_of,
)
from ._speed_map import raw_power_map, speed_weights
from ._state import check_document, model_state, read_json_document, restore_state
from .freerun import FreeRunDivergenceError, free_run
from .selection import warn_conditioning
from .sweep_data import read_sample_table
from .terms import channel_counts, parse_terms, split_noise_terms

__all__ = ["SpeedScheduledNarx", "SpeedExtrapolationWarning", "SimulationInterval"]


def _process_structure(names):
    """Exponents and lags of the process terms, or Nones when they are not NARX terms."""
    process = split_noise_terms(names)[0]
    if channel_counts(names) != (1, 1):  # one output of a multi-output model
        return None, None, None
    try:
        return parse_terms([names[i] for i in process])
    except ValueError:
        return None, None, None


class SpeedScheduledNarx(RegressorMixin, BaseEstimator):
    """Polynomial NARX model with a common structure and speed-dependent coefficients.

    ``y(t) = sum_m theta_m(omega) * p_m(y(t-1..ny), u(t-1..nu))`` where the terms
    ``p_m`` are chosen once for all speeds by AERR-based EFOR
    (:class:`CommonStructureEFOR`), the per-speed coefficients come from inverse
    Gram-Schmidt, and each ``theta_m(omega)`` is a polynomial of degree
    ``coef_degree`` in the speed ``omega`` (rad/s), fitted by least squares.

    Parameters
    ----------
    ny, nu : int, default=3
        Output and input lags.
    degree : int, default=3
        Polynomial degree of the NARX terms.
    esr : float, default=0.01
        Selection stops when the error-to-signal ratio (percent) falls below it.
    max_terms : int or None, default=None
        Largest number of selected terms.
    coef_degree : int or None, default=None
        Degree of the coefficient polynomials in speed; None means 3 (the paper's),
        or fewer when fewer than four speeds are given (``coef_degree_``).
        With ``speed_basis='spline'`` the model's coefficients follow the spline and
        this only sets the degree of the reported ``speed_polynomials_`` (Table 4),
        so setting it there warns: in a grid search, search it with
        ``speed_basis='polynomial'`` only (a list of parameter grids).
    speed_basis : {'polynomial', 'spline'}, default='polynomial'
        How coefficients depend on speed: one global least-squares polynomial of
        degree ``coef_degree`` (the paper), or a natural cubic spline through the
        per-speed coefficients, which follows sharp changes near a critical
        speed without the oscillation of a global polynomial.
    solver : {'gram', 'qr'}, default='gram'
        Compression of each dataset; see :class:`CommonStructureEFOR`.
    tol : float, default=1e-12
        Relative linear-dependence tolerance of the orthogonalisation.
    prune : bool, default=True
        Backward elimination of terms not needed to meet ``esr`` after the
        forward pass; ``False`` is the paper's method exactly.
    noise_lags : int, default=0
        NARMAX identification when positive: after the process terms are
        selected, noise terms ``e(t-1) .. e(t-noise_lags)`` (a moving-average model
        of the equation error) are admitted by a likelihood-ratio test pooled over
        the speeds and estimated by extended least squares with prediction-error
        refinement, iterated until the coefficients settle. This removes the bias
        that coloured noise gives NARX least squares. ``0`` is plain NARX. In a
        Pipeline, noise columns made by ``NarxTermDictionary(noise_lags=...)`` are
        estimated the same way (their selection is then the selector's).
    selection : {'one_step', 'simulation'}, default='one_step'
        How ``fit(datasets, speeds)`` chooses the terms. ``'one_step'``: AERR-based
        EFOR on the one-step-ahead error (the paper's). ``'simulation'``: by the
        free-run (simulation) error pooled over all records and speeds, starting from
        the better-simulating of the linear model and the one-step selection, and
        pruning terms the free run does not need (Piroddi & Spinelli 2003,
        :mod:`sknarx.narx._simulation_selection`); no kept structure diverges on its
        training records. ``esr`` and ``prune`` then do not apply;
        ``max_terms`` (default 30) caps the search. On real data (the Silverbox
        benchmark) it is the better choice.
    refine : {None, 'output_error'}, default=None
        ``'output_error'``: after selection, each speed's coefficients minimise the
        free-run error of its records (Levenberg-Marquardt with exact sensitivities
        through the recursion), and their covariance is the output-error one,
        ``sigma^2 (J^T J)^-1``; with ``speed_basis='polynomial'`` the speed polynomials
        are then refined the same way on all speeds' records at once (each speed
        weighted by its simulation-error variance), with their joint covariance
        ``coef_poly_cov_``. ``None`` keeps the least-squares coefficients.
    simulation_tol : float, default=0.002
        ``selection='simulation'`` stops when the best further term lowers the pooled
        simulation error by less than this share of it, and prunes a term whose removal
        raises it by less (0.2 %: the knee of a 5-fold cross-validation over the
        Silverbox estimation records, never its test data; see docs/decisions.md).
    n_jobs : int or None, default=None
        Parallel candidate evaluations of ``selection='simulation'`` (joblib threads;
        the free run is compiled and releases the GIL). None: one, or the active
        ``joblib.parallel_config``.

    Attributes
    ----------
    selected_terms_ : list of str
        Term names in selection order; noise terms ``e(t-k)`` (NARMAX) last.
    noise_terms_ : list of str
        The noise terms among them (empty for a NARX model). The free run
        (:meth:`simulate`) uses the process terms only.
    exponents_ : ndarray of shape (n_process_terms, ny_ + nu_)
        Exponents of the selected process terms over ``y(t-1..ny_), u(t-1..nu_)``.
    ny_, nu_ : int
        Largest lags used by the selected terms.
    aerr_ : ndarray
        AERR of each selected term (percent).
    esr_ : float
        Final error-to-signal ratio (percent).
    speeds_ : ndarray or None
        Training speeds (rad/s), sorted as given.
    coef_per_speed_ : DataFrame (n_speeds, n_terms)
        Inverse Gram-Schmidt coefficients per training speed (the paper's Table 3).
    coef_std_err_per_speed_ : DataFrame (n_speeds, n_terms)
        Their standard errors: ``sigma_k^2 (P_k^T P_k)^-1`` propagated along the
        inverse Gram-Schmidt path, with ``sigma_k^2`` the one-step residual variance
        (for NARMAX models, the prediction-error covariance).
    coef_cov_per_speed_ : ndarray (n_speeds, n_terms, n_terms)
        Full covariance of each speed's coefficients (term order as above).
    noise_variance_per_speed_ : ndarray (n_speeds,)
        Residual (equation-error) variance per speed, in output units squared.
    dof_per_speed_ : ndarray (n_speeds,)
        Residual degrees of freedom per speed (regression rows minus terms).
    n_iter_ : int
        Extended-least-squares iterations (0 for a NARX model).
    speed_polynomials_ : DataFrame (n_terms, coef_degree + 1)
        ``beta_j`` of ``theta_m(omega) = sum_j beta_j omega^j`` (Table 4), in
        powers of omega in rad/s. Evaluation uses the better conditioned scaled
        form in ``coef_poly_``.
    speed_polynomials_std_err_ : DataFrame (n_terms, coef_degree + 1)
        Standard errors of ``speed_polynomials_``, propagated from the per-speed
        covariances (the records are independent); see also
        :meth:`bootstrap_speed_function`.
    coef_poly_ : ndarray (n_terms, coef_degree + 1)
        Coefficients in the scaled speed ``s = (2 omega - a - b) / (b - a)``.
    coef_poly_cov_ : ndarray or None
        Joint covariance of ``coef_poly_.ravel()`` when the speed functions were
        refined on the free-run error (``refine='output_error'``); standard errors and
        :meth:`simulate_interval` then use it. None otherwise.
    coef_degree_ : int
        The speed-polynomial degree in force.
    speed_range_ : tuple of float or None
        ``(a, b)``: smallest and largest training speed.
    output_scale_ : float
        Largest absolute training output; free runs beyond ``1e3`` times it diverge.
    condition_number_ : float
    n_features_in_ : int
        Only when fitted on a term matrix (pipeline use).

    Examples
    --------
    >>> import numpy as np
    >>> from sknarx import SpeedScheduledNarx
    >>> rng = np.random.default_rng(1)
    >>> speeds = np.array([100.0, 150.0, 200.0, 250.0])
    >>> data = []
    >>> for w in speeds:
    ...     u = rng.standard_normal(300); y = np.zeros(300)
    ...     for t in range(1, 300):
    ...         y[t] = (0.2 + 1e-3 * w) * y[t - 1] + u[t - 1]
    ...     data.append((u, y))
    >>> model = SpeedScheduledNarx(ny=1, nu=1, degree=1, coef_degree=1, max_terms=2)
    >>> model = model.fit(data, speeds)
    >>> model.selected_terms_
    ['u(t-1)', 'y(t-1)']
    >>> round(float(model.coefficients_at(175.0)[1]), 6)
    0.375

    Records without a speed (one operating point, e.g. a circuit) share one set of
    coefficients; here terms are chosen by free-run error and refined on it:

    >>> u = rng.standard_normal(400); y = np.zeros(400)
    >>> for t in range(2, 400):
    ...     y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] - 0.1 * y[t - 1] ** 3 + u[t - 1]
    >>> m = SpeedScheduledNarx(ny=2, nu=1, degree=3, selection="simulation",
    ...                        refine="output_error").fit([(u, y)])
    >>> sorted(m.selected_terms_)
    ['u(t-1)', 'y(t-1)', 'y(t-1)^3', 'y(t-2)']
    >>> round(float(m.coefficients_at(0.0)[m.selected_terms_.index("y(t-1)^3")]), 6)
    -0.1
    """

    _parameter_constraints = {
        "ny": [Interval(Integral, 0, None, closed="left")],
        "nu": [Interval(Integral, 0, None, closed="left")],
        "degree": [Interval(Integral, 0, None, closed="left")],
        "esr": [Interval(Real, 0, 100, closed="both")],
        "max_terms": [Interval(Integral, 1, None, closed="left"), None],
        "coef_degree": [Interval(Integral, 0, None, closed="left"), None],
        "speed_basis": [StrOptions({"polynomial", "spline"})],
        "solver": [StrOptions({"gram", "qr"})],
        "tol": [Interval(Real, 0, 1, closed="left")],
        "prune": ["boolean"],
        "noise_lags": [Interval(Integral, 0, None, closed="left")],
        "selection": [StrOptions({"one_step", "simulation"})],
        "refine": [StrOptions({"output_error"}), None],
        "simulation_tol": [Interval(Real, 0, 1, closed="left")],
        "n_jobs": [Integral, None],
    }

    def __init__(
        self,
        ny=3,
        nu=3,
        degree=3,
        esr=0.01,
        max_terms=None,
        coef_degree=None,
        speed_basis="polynomial",
        solver="gram",
        tol=1e-12,
        prune=True,
        noise_lags=0,
        selection="one_step",
        refine=None,
        simulation_tol=0.002,
        n_jobs=None,
    ):
        self.ny = ny
        self.nu = nu
        self.degree = degree
        self.esr = esr
        self.max_terms = max_terms
        self.coef_degree = coef_degree
        self.speed_basis = speed_basis
        self.solver = solver
        self.tol = tol
        self.prune = prune
        self.noise_lags = noise_lags
        self.selection = selection
        self.refine = refine
        self.simulation_tol = simulation_tol
        self.n_jobs = n_jobs

    # ------------------------------------------------------------------ fit
    def fit(self, X, y=None):
        """Identify the model.

        Two calling conventions:

        * ``fit(datasets, speeds)``: ``datasets`` is a list of ``(u, y)`` 1-D array
          pairs (or a long DataFrame with columns ``speed``, ``u``, ``y``, with
          ``speeds`` omitted) and ``speeds`` the speed of each, in rad/s. The
          dictionary, the common-structure selection and the coefficients are all
          computed here, in one chunked pass over the data.
        * ``fit(X, y)`` inside a Pipeline: ``X`` is the selected term matrix (a
          DataFrame with term-name columns and a ``speed`` index, as produced by
          :class:`NarxTermDictionary` and :class:`CommonStructureEFOR`) and ``y``
          the output; the terms are taken as given, in that order.

        Returns
        -------
        self : SpeedScheduledNarx
        """
        self._validate_params()
        if self.speed_basis == "spline" and self.coef_degree is not None:
            warnings.warn(
                f"coef_degree={self.coef_degree} does not change a speed_basis='spline' "
                "model (its coefficients follow the spline); it only sets the degree of the "
                "reported speed_polynomials_. Leave it None, or search it with "
                "speed_basis='polynomial' only.",
                UserWarning, stacklevel=2)
        for attr in ("n_features_in_", "feature_names_in_"):
            if hasattr(self, attr):
                delattr(self, attr)
        fitted = fit_sweep(self, X, y) if is_sweep(X) else fit_terms(self, X, y)
        return self._set_fitted(fitted)

    def _set_fitted(self, fitted: _Fit):
        """The fitted attributes from one fitting path's result (shared with the
        multi-output model, which fits one of these per output)."""
        warn_conditioning(fitted.cond, fitted.speeds, self.solver)
        names, speeds = fitted.names, fitted.speeds
        index = pd.Index(speeds, name="speed") if speeds is not None else None
        self.selected_terms_ = names
        self.noise_terms_ = [names[i] for i in split_noise_terms(names)[1]]
        self.aerr_ = fitted.aerr
        self.esr_ = float(fitted.esr)
        self.condition_number_ = float(np.max(fitted.cond))
        self.n_iter_ = int(fitted.n_iter)
        self.coef_per_speed_ = pd.DataFrame(fitted.coef, columns=names, index=index)
        self.coef_cov_per_speed_ = fitted.cov
        std = np.sqrt(np.clip(np.einsum("kii->ki", fitted.cov), 0.0, None))
        self.coef_std_err_per_speed_ = pd.DataFrame(std, columns=names, index=index)
        self.noise_variance_per_speed_ = fitted.sigma2
        self.dof_per_speed_ = fitted.dof
        self.err_ = pd.DataFrame(fitted.err, columns=names, index=index)
        self.speeds_ = speeds
        self.coef_degree_ = self._resolve_degree(1 if speeds is None else np.unique(speeds).size)
        self.exponents_, self.ny_, self.nu_ = _process_structure(names)
        fit_speed_polynomials(self, fitted.coef, speeds)
        self.coef_poly_cov_ = None
        if (self.refine == "output_error" and fitted.records is not None
                and self.speed_basis == "polynomial" and self.speed_range_ is not None
                and self.speed_range_[0] < self.speed_range_[1]):
            refine_speed_functions_of(self, fitted)
        return self

    def _resolve_degree(self, n_speeds):
        """The speed-polynomial degree for ``n_speeds`` speeds: ``coef_degree``, or when
        None 3 (the paper's) capped by the number of speeds."""
        if self.coef_degree is None:
            return int(max(min(3, n_speeds - 1), 0))
        return int(self.coef_degree)

    def _check_speeds(self, speeds):
        if not np.all(np.isfinite(speeds)):
            raise ValueError("Speeds must be finite numbers (rad/s).")
        uniq, counts = np.unique(speeds, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(
                f"Duplicate speeds {uniq[counts > 1].tolist()} rad/s: each dataset needs its own "
                "speed. Merge or drop repeated records."
            )
        if self.speed_basis == "spline" and speeds.size < 3:
            raise ValueError(
                f"{speeds.size} speed(s) are too few for speed_basis='spline': at least 3 are "
                "needed."
            )
        degree = self._resolve_degree(speeds.size)
        if self.speed_basis == "polynomial" and speeds.size < degree + 1:
            raise ValueError(
                f"{speeds.size} speed(s) cannot determine coefficient polynomials of degree "
                f"{degree}: at least {degree + 1} distinct speeds are needed. Add speeds or "
                "lower coef_degree."
            )

    def coefficients_at(self, omega, return_std=False):
        """Coefficients ``theta(omega)`` of the selected terms.

        Parameters
        ----------
        omega : float or array-like of shape (n,)
            Speed(s) in rad/s.
        return_std : bool, default=False
            Also return the standard error of each coefficient function at
            ``omega``, propagated from the per-speed covariances through the
            speed basis (a pointwise band is ``theta +- 1.96 std``).

        Returns
        -------
        theta : ndarray of shape (n_terms,) or (n, n_terms)
        std : ndarray of the same shape
            Only with ``return_std=True``.
        """
        check_is_fitted(self, "coef_poly_")
        theta = coefficients_at(self, omega)
        if not return_std:
            return theta
        return theta, coefficient_std(self, omega)

    def simulate(self, u, omega=None, y0=None, on_divergence="raise"):
        """Free-run the model from the input alone (model predicted output).

        Parameters
        ----------
        u : array-like of shape (n_samples,)
            Input (e.g. the unbalance force, N).
        omega : float or array-like of shape (n_samples,), optional
            Speed in rad/s: constant, or one value per sample for a run-up or
            coast-down. Needed by a speed-scheduled model; a model fitted without
            speeds takes none.
        y0 : array-like of shape (max_lag,), optional
            Initial outputs ``y(0..max_lag-1)``; zeros (rest) by default.
        on_divergence : {'raise', 'warn'}, default='raise'
            What to do when ``|y|`` exceeds ``1e3 * output_scale_``: raise
            :class:`FreeRunDivergenceError`, or warn and return NaN from there on.

        Returns
        -------
        y : ndarray of shape (n_samples,)
        """
        u, w = self._check_run(u, omega)
        process = split_noise_terms(self.selected_terms_)[0]
        theta = np.atleast_2d(self.coefficients_at(float(w) if w.ndim == 0 else w))[:, process]
        yhat, at = free_run(u, theta, self.exponents_, self.ny_, self.nu_, y0=y0,
                            bound=self._bound())
        if at >= 0:
            fix = ("choose the terms by free-run error (selection='simulation'), refine "
                   "them on it (refine='output_error'), or use fewer terms (max_terms) or "
                   "a lower term degree")
            if self.speed_range_ is None:
                where, fix = "", "The identified model is unstable on this input; " + fix
            else:
                wt = float(w) if w.ndim == 0 else float(w[at])
                where = f" (speed {wt:g} rad/s)"
                fix = ("The identified model is unstable there; add training speeds near "
                       "it, lower coef_degree, or " + fix)
            msg = (f"The free run diverged at sample {at}{where}: |y| exceeded "
                   f"{self._bound():.3g}, 1000 times the largest training output. {fix}.")
            if on_divergence == "raise":
                raise FreeRunDivergenceError(msg)
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
        return yhat

    def _bound(self):
        return 1e3 * self.output_scale_ if self.output_scale_ > 0 else np.inf

    def _check_run(self, u, omega):
        check_is_fitted(self, "coef_poly_")
        if self.exponents_ is None:
            raise ValueError(
                "This model was fitted on columns whose names are not NARX terms "
                f"({self.selected_terms_[:3]}...), so it cannot be simulated; fit it on the "
                "output of NarxTermDictionary or with fit(datasets, speeds)."
            )
        u = np.asarray(u, dtype=float)
        if u.ndim != 1:
            raise ValueError(f"u must be 1-D, got shape {u.shape}.")
        if not np.all(np.isfinite(u)):
            raise ValueError("u contains NaN/inf.")
        if omega is None:
            if self.speed_range_ is not None:
                raise ValueError(
                    "This model is speed-scheduled: give the speed omega (rad/s), one value "
                    "or one per sample.")
            omega = 0.0
        w = np.asarray(omega, dtype=float)
        if w.ndim != 0 and w.shape != u.shape:
            raise ValueError(
                f"omega must be a scalar or have one value per sample ({u.shape[0]}); got "
                f"shape {w.shape}."
            )
        if not np.all(np.isfinite(w)):
            raise ValueError("omega must be finite (rad/s).")
        return u, w

    def simulate_interval(self, u, omega, y0=None, n_draws=200, level=0.95,
                          random_state=None):
        """Free run with a Monte-Carlo prediction band from the coefficient uncertainty.

        Each draw takes every training speed's coefficients from their estimated
        normal distribution (``coef_per_speed_``, ``coef_cov_per_speed_``; the speeds
        are independent records), maps them through the speed basis exactly as the
        fit does, and free-runs the model. The band is the pointwise quantiles of
        the draws that stayed bounded; the share that diverged is reported.

        Parameters
        ----------
        u : array-like of shape (n_samples,)
            Input (e.g. the unbalance force, N).
        omega : float or array-like of shape (n_samples,)
            Speed in rad/s, constant or one value per sample.
        y0 : array-like of shape (max_lag,), optional
            Initial outputs; zeros by default.
        n_draws : int, default=200
        level : float, default=0.95
            Coverage of the band.
        random_state : int, RandomState instance or None

        Returns
        -------
        SimulationInterval
        """
        return simulate_interval(self, u, omega, y0, n_draws, level,
                                 random_state)

    def predict(self, X):
        """Predict the output.

        Parameters
        ----------
        X : DataFrame, list of (u, y) pairs, or term matrix
            A long sample table (columns ``speed``, ``u`` and optionally ``y``):
            free-run prediction of every dataset, started from the measured
            first outputs when ``y`` is present. A term matrix (pipeline use):
            one-step-ahead prediction ``sum_m theta_m(speed) * X[:, m]``.

        Returns
        -------
        y_pred : ndarray of shape (n_samples,)
        """
        check_is_fitted(self, "coef_poly_")
        if isinstance(X, pd.DataFrame) and "u" in X.columns:
            datasets, has_speed = read_sample_table(X, require_y=False)
            out = []
            lag = max(self.ny_, self.nu_)
            for d in datasets:
                y0 = d.y[:lag] if np.all(np.isfinite(d.y[:lag])) else None
                out.append(self.simulate(d.u, d.speed if has_speed else 0.0, y0=y0))
            return np.concatenate(out)
        if not hasattr(self, "n_features_in_"):
            raise ValueError(
                "This model was fitted with fit(datasets, speeds); predict needs a long "
                "sample table (a DataFrame with columns 'speed', 'u'[, 'y']) or use simulate()."
            )
        speeds = None
        if isinstance(X, pd.DataFrame) and X.index.name == "speed":
            speeds = X.index.to_numpy(dtype=float)
        P = check_nan_rows(validate_data(self, X, reset=False, ensure_all_finite="allow-nan",
                                         dtype=np.float64))
        if speeds is None or self.speed_range_ is None:
            theta = self.coef_poly_[:, 0] if self.speed_range_ is None else None
            if theta is None:
                raise ValueError(
                    "This model is speed-scheduled: X needs an index named 'speed' (rad/s)."
                )
            return P @ theta
        uniq, inv = np.unique(speeds, return_inverse=True)
        theta = self.coefficients_at(uniq)[inv]
        return np.einsum("ij,ij->i", P, theta)

    # ---------------------------------------------------------- utilities
    def score(self, X, y, sample_weight=None):
        """Coefficient of determination R^2 of :meth:`predict`.

        With a term matrix (Pipeline use) the prediction is one step ahead and the
        first ``max_lag`` samples of each dataset, which have no complete history
        (all-NaN rows), are left out; with a long sample table it is the free run.

        Parameters
        ----------
        X : DataFrame, list of (u, y) pairs, or term matrix
            As for :meth:`predict`.
        y : array-like of shape (n_samples,)
        sample_weight : array-like of shape (n_samples,), optional

        Returns
        -------
        score : float
        """
        from sklearn.metrics import r2_score

        y_pred = self.predict(X)
        y = np.asarray(y, dtype=float)
        ok = np.isfinite(y_pred)
        w = None if sample_weight is None else np.asarray(sample_weight)[ok]
        return float(r2_score(y[ok], y_pred[ok], sample_weight=w))

    def summary(self, kind="per_speed"):
        """Results table of the fitted model.

        Parameters
        ----------
        kind : {'per_speed', 'speed_function'}, default='per_speed'
            ``'per_speed'``: one row per training speed and selected term, with the
            per-speed least-squares coefficient (not the speed function) and its
            standard error. ``'speed_function'``: one row per term and parameter of
            the coefficient functions: the raw-power polynomial coefficients
            ``beta_j`` (``theta(omega) = sum_j beta_j omega^j``, omega in rad/s) for
            ``speed_basis='polynomial'``, the knot values ``theta(omega_k)`` for
            ``'spline'``; standard errors propagated from the per-speed covariances.

        Returns
        -------
        table : DataFrame
            ``per_speed`` columns: ``speed`` (rad/s), ``term``, ``kind`` (process or
            noise), ``coef``, ``std_err``, ``t_value``, ``err`` (percent of that
            speed's output energy the term removed at its selection step),
            ``aerr`` (percent, averaged over speeds). ``speed_function`` columns:
            ``term``, ``parameter``, ``value``, ``std_err``.
        """
        check_is_fitted(self, "coef_poly_")
        if kind == "per_speed":
            coef = self.coef_per_speed_
            se = self.coef_std_err_per_speed_.to_numpy()
            speeds = (np.full(coef.shape[0], np.nan) if self.speeds_ is None
                      else np.asarray(self.speeds_, dtype=float))
            noise = set(self.noise_terms_)
            rows = []
            for k in range(coef.shape[0]):
                for m, term in enumerate(self.selected_terms_):
                    c, e = float(coef.iloc[k, m]), float(se[k, m])
                    rows.append({"speed": speeds[k], "term": term,
                                 "kind": "noise" if term in noise else "process",
                                 "coef": c, "std_err": e,
                                 "t_value": c / e if e > 0 else np.nan,
                                 "err": 100.0 * float(self.err_.iloc[k, m]),
                                 "aerr": float(self.aerr_[m])})
            return pd.DataFrame(rows)
        if kind == "speed_function":
            if self.speed_basis == "spline" and self.speeds_ is not None:
                values = self.coef_per_speed_.to_numpy().T
                errors = self.coef_std_err_per_speed_.to_numpy().T
                params = [f"theta({w:g} rad/s)" for w in self.speeds_]
            else:
                values = self.speed_polynomials_.to_numpy()
                errors = self.speed_polynomials_std_err_.to_numpy()
                params = list(self.speed_polynomials_.columns)
            rows = [{"term": term, "parameter": p, "value": float(values[m, j]),
                     "std_err": float(errors[m, j])}
                    for m, term in enumerate(self.selected_terms_)
                    for j, p in enumerate(params)]
            return pd.DataFrame(rows)
        raise ValueError(f"kind must be 'per_speed' or 'speed_function', got {kind!r}.")

    def bootstrap_speed_function(self, n_resamples=200, random_state=None):
        """Standard errors of the speed-function parameters by a bootstrap over speeds.

        The propagated errors of :meth:`summary` assume the speed function is
        right; when the per-speed coefficients scatter about it more than their own
        errors explain (the polynomial cannot follow them), they are too small.
        Resampling the training speeds (whole records) with replacement and
        refitting the speed function captures that scatter.

        Parameters
        ----------
        n_resamples : int, default=200
        random_state : int, RandomState instance or None

        Returns
        -------
        table : DataFrame
            As ``summary(kind='speed_function')``, with ``std_err`` from the
            bootstrap (resamples with too few distinct speeds are redrawn).
        """
        check_is_fitted(self, "coef_poly_")
        table = self.summary(kind="speed_function")
        if self.speeds_ is None or len(self.speeds_) < 2:
            raise ValueError("A bootstrap over speeds needs a model fitted at several speeds.")
        rng = check_random_state(random_state)
        speeds = np.asarray(self.speeds_, dtype=float)
        Theta = self.coef_per_speed_.to_numpy()
        K = speeds.size
        need = 3 if self.speed_basis == "spline" else self.coef_degree_ + 1
        if np.unique(speeds).size < need:
            raise ValueError(f"{K} speeds are too few for a bootstrap of this speed basis.")
        draws = []
        while len(draws) < n_resamples:
            idx = rng.randint(0, K, K)
            uniq = np.unique(idx)
            if uniq.size < need:
                continue
            if self.speed_basis == "spline":
                L = speed_weights(speeds[uniq], speeds, "spline", 0)
                draws.append((L @ Theta[uniq]).T)
            else:
                draws.append(raw_power_map(speeds[idx], self.coef_degree_) @ Theta[idx])
                draws[-1] = draws[-1].T
        table["std_err"] = np.std(np.stack(draws), axis=0, ddof=1).reshape(-1)
        return table

    def to_json(self, path=None) -> str:
        """Serialise the fitted model to JSON text (and write it to ``path`` if given).

        The document holds the parameters, selected terms, per-speed coefficients
        with their covariances, and the speed functions; floats round-trip exactly.
        """
        check_is_fitted(self, "coef_poly_")
        text = json.dumps(json_safe(model_state(self)), indent=1)
        if path is not None:
            write_text_atomic(path, text)
        return text

    @classmethod
    def from_json(cls, source):
        """Rebuild a fitted model from :meth:`to_json` output (JSON text or a path)."""
        return cls._from_document(read_json_document(source))

    @classmethod
    def _from_document(cls, doc):
        """The fitted model of one document (also one output of a multi-output model)."""
        check_document(doc)
        model = cls(**doc["params"])
        restore_state(model, doc)
        model.exponents_, model.ny_, model.nu_ = _process_structure(model.selected_terms_)
        model.coef_degree_ = model.speed_polynomials_.shape[1] - 1
        model.coef_spline_ = None
        if model.speed_basis == "spline" and model.speeds_ is not None:
            # the spline is a deterministic function of the per-speed coefficients
            model.coef_spline_ = _spline(model.speeds_, model.coef_per_speed_.to_numpy())
        return model

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
