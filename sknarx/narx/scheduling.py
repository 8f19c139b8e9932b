"""SpeedScheduledNarx: a common-structure NARX whose coefficients are polynomials in speed."""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
import pandas as pd
from numpy.polynomial import Polynomial
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted, validate_data

from ._design import check_nan_rows, read_term_matrix
from ._orthogonal import compress, termset_blocks
from .freerun import FreeRunDivergenceError, free_run
from .selection import compress_groups, fit_efor, warn_conditioning
from .sweep_data import as_datasets, check_series, read_sample_table
from .terms import TermSet, monomial_exponents, parse_terms, term_names

__all__ = ["SpeedScheduledNarx", "SpeedExtrapolationWarning"]


def _spline(speeds, coef):
    from scipy.interpolate import CubicSpline

    order = np.argsort(speeds)
    return CubicSpline(np.asarray(speeds)[order], np.asarray(coef)[order], axis=0,
                       bc_type="natural")


class SpeedExtrapolationWarning(UserWarning):
    """A requested speed lies outside the range of the fitted speeds."""


def _is_sweep(X) -> bool:
    if isinstance(X, pd.DataFrame):
        return "u" in X.columns
    if isinstance(X, (list, tuple)) and len(X) > 0:
        first = X[0]
        return isinstance(first, (list, tuple)) and len(first) == 2 and np.ndim(first[0]) == 1
    return False


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
    coef_degree : int, default=3
        Degree of the coefficient polynomials in speed (the paper uses 3).
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

    Attributes
    ----------
    selected_terms_ : list of str
        Term names in selection order.
    exponents_ : ndarray of shape (n_terms, ny_ + nu_)
        Exponents of the selected terms over ``y(t-1..ny_), u(t-1..nu_)``.
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
    speed_polynomials_ : DataFrame (n_terms, coef_degree + 1)
        ``beta_j`` of ``theta_m(omega) = sum_j beta_j omega^j`` (Table 4), in
        powers of omega in rad/s. Evaluation uses the better conditioned scaled
        form in ``coef_poly_``.
    coef_poly_ : ndarray (n_terms, coef_degree + 1)
        Coefficients in the scaled speed ``s = (2 omega - a - b) / (b - a)``.
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
    """

    _parameter_constraints = {
        "ny": [Interval(Integral, 0, None, closed="left")],
        "nu": [Interval(Integral, 0, None, closed="left")],
        "degree": [Interval(Integral, 0, None, closed="left")],
        "esr": [Interval(Real, 0, 100, closed="both")],
        "max_terms": [Interval(Integral, 1, None, closed="left"), None],
        "coef_degree": [Interval(Integral, 0, None, closed="left")],
        "speed_basis": [StrOptions({"polynomial", "spline"})],
        "solver": [StrOptions({"gram", "qr"})],
        "tol": [Interval(Real, 0, 1, closed="left")],
        "prune": ["boolean"],
    }

    def __init__(
        self,
        ny=3,
        nu=3,
        degree=3,
        esr=0.01,
        max_terms=None,
        coef_degree=3,
        speed_basis="polynomial",
        solver="gram",
        tol=1e-12,
        prune=True,
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
        for attr in ("n_features_in_", "feature_names_in_"):
            if hasattr(self, attr):
                delattr(self, attr)
        if _is_sweep(X):
            res, coef, cond, names, speeds = self._fit_sweep(X, y)
        else:
            res, coef, cond, names, speeds = self._fit_terms(X, y)
        warn_conditioning(cond, speeds)
        self.selected_terms_ = names
        self.aerr_ = res.aerr
        self.esr_ = float(res.esr)
        self.condition_number_ = float(np.max(cond))
        index = pd.Index(speeds, name="speed") if speeds is not None else None
        self.coef_per_speed_ = pd.DataFrame(coef, columns=names, index=index)
        self.err_ = pd.DataFrame(res.err, columns=names, index=index)
        self.speeds_ = speeds
        try:
            self.exponents_, self.ny_, self.nu_ = parse_terms(names)
        except ValueError:
            self.exponents_, self.ny_, self.nu_ = None, None, None
        self._fit_speed_polynomials(coef, speeds)
        return self

    def _fit_sweep(self, X, speeds):
        datasets = as_datasets(X, speeds)
        ws = np.array([d.speed for d in datasets])
        self._check_speeds(ws)
        lag = max(self.ny, self.nu)
        termset = TermSet(monomial_exponents(self.ny, self.nu, self.degree), self.ny, self.nu)
        names_all = term_names(termset.exponents, self.ny, self.nu)
        width = len(names_all) + 1
        Zs, norms, scale = [], [], 0.0
        for k, d in enumerate(datasets):
            where = f"Dataset {k} (speed {d.speed:g} rad/s)"
            u, yk = check_series(d.u, d.y, d.speed, lag + 2, where)
            if self.nu > 0 and self.degree > 0 and np.ptp(u) == 0:
                raise ValueError(
                    f"{where}: the input u is constant ({u[0]:g}), so the input terms are "
                    "collinear with the constant and the regression is singular. Use a "
                    "record where the input varies (e.g. the unbalance force m e w^2 cos wt)."
                )
            if not np.any(yk[lag:]):
                raise ValueError(f"{where}: the output y is identically zero.")
            Z, nrm = compress(termset_blocks(termset, u, yk, lag), width, self.solver)
            Zs.append(Z)
            norms.append(nrm)
            scale = max(scale, float(np.max(np.abs(yk))))
        self.output_scale_ = scale
        res, coef, cond = fit_efor(np.stack(Zs), np.stack(norms), self.esr,
                                   self.max_terms, self.tol, prune=self.prune)
        return res, coef, cond, [names_all[j] for j in res.selected], ws

    def _fit_terms(self, X, y):
        tm = read_term_matrix(self, X, y, "SpeedScheduledNarx")
        speeds = tm.dataset_speeds()
        if speeds is not None:
            self._check_speeds(speeds)
        Z, norms = compress_groups(tm, self.solver)
        try:
            res, coef, cond = fit_efor(Z, norms, None, None, self.tol,
                                       order=range(tm.P.shape[1]))
        except np.linalg.LinAlgError as exc:
            raise ValueError(
                f"SpeedScheduledNarx: the given terms are linearly dependent ({exc}); "
                "drop the redundant columns."
            ) from exc
        ok = ~np.all(np.isnan(tm.P), axis=1)
        self.output_scale_ = float(np.max(np.abs(tm.y[ok])))
        return res, coef, cond, tm.names, speeds

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
        if self.speed_basis == "polynomial" and speeds.size < self.coef_degree + 1:
            raise ValueError(
                f"{speeds.size} speed(s) cannot determine coefficient polynomials of degree "
                f"{self.coef_degree}: at least {self.coef_degree + 1} distinct speeds are "
                "needed. Add speeds or lower coef_degree."
            )

    def _fit_speed_polynomials(self, coef, speeds):
        names = self.selected_terms_
        if speeds is None:
            # No speeds: one operating point, constant coefficients.
            self.speed_range_ = None
            self.coef_poly_ = coef[:1].T.copy()
            self.speed_polynomials_ = pd.DataFrame(self.coef_poly_, index=names, columns=["beta0"])
            return
        a, b = float(np.min(speeds)), float(np.max(speeds))
        self.speed_range_ = (a, b)
        self.coef_spline_ = None
        if self.speed_basis == "spline":
            self.coef_spline_ = _spline(speeds, coef)
        J = self.coef_degree
        if a == b:  # a single speed (then coef_degree is 0): constant coefficients
            self.coef_poly_ = coef[:1].T.copy()
            self.speed_polynomials_ = pd.DataFrame(self.coef_poly_, index=names,
                                                   columns=["beta0"])
            return
        polys = [Polynomial.fit(speeds, coef[:, m], J, domain=[a, b]) for m in range(coef.shape[1])]
        self.coef_poly_ = np.array([np.pad(p.coef, (0, J + 1 - p.coef.size)) for p in polys])
        raw_coefs = [p.convert().coef for p in polys]  # powers of omega in rad/s
        raw = np.array([np.pad(c, (0, J + 1 - c.size)) for c in raw_coefs])
        self.speed_polynomials_ = pd.DataFrame(
            raw, index=names, columns=[f"beta{j}" for j in range(J + 1)]
        )

    # ------------------------------------------------------------ evaluate
    def coefficients_at(self, omega):
        """Coefficients ``theta(omega)`` of the selected terms.

        Parameters
        ----------
        omega : float or array-like of shape (n,)
            Speed(s) in rad/s.

        Returns
        -------
        theta : ndarray of shape (n_terms,) or (n, n_terms)
        """
        check_is_fitted(self, "coef_poly_")
        w = np.asarray(omega, dtype=float)
        if self.speed_range_ is None:
            out = np.broadcast_to(self.coef_poly_[:, 0], w.shape + (self.coef_poly_.shape[0],))
            return np.array(out)
        if not np.all(np.isfinite(w)):
            raise ValueError("omega must be finite (rad/s).")
        a, b = self.speed_range_
        if np.any((w < a) | (w > b)):
            lo, hi = float(np.min(w)), float(np.max(w))
            warnings.warn(
                f"Speed(s) {lo:g}..{hi:g} rad/s lie outside the fitted range {a:g}..{b:g} "
                "rad/s; the coefficient polynomials are extrapolated and the model may be "
                "inaccurate or unstable there.",
                SpeedExtrapolationWarning,
                stacklevel=2,
            )
        if getattr(self, "coef_spline_", None) is not None:
            return self.coef_spline_(w)
        s = (2.0 * w - a - b) / (b - a) if b > a else np.zeros_like(w)
        return np.moveaxis(np.polynomial.polynomial.polyval(s, self.coef_poly_.T), 0, -1)

    def simulate(self, u, omega, y0=None, on_divergence="raise"):
        """Free-run the model from the input alone (model predicted output).

        Parameters
        ----------
        u : array-like of shape (n_samples,)
            Input (e.g. the unbalance force, N).
        omega : float or array-like of shape (n_samples,)
            Speed in rad/s: constant, or one value per sample for a run-up or
            coast-down.
        y0 : array-like of shape (max_lag,), optional
            Initial outputs ``y(0..max_lag-1)``; zeros (rest) by default.
        on_divergence : {'raise', 'warn'}, default='raise'
            What to do when ``|y|`` exceeds ``1e3 * output_scale_``: raise
            :class:`FreeRunDivergenceError`, or warn and return NaN from there on.

        Returns
        -------
        y : ndarray of shape (n_samples,)
        """
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
        w = np.asarray(omega, dtype=float)
        if w.ndim == 0:
            theta = self.coefficients_at(float(w))[None, :]
        elif w.shape == u.shape:
            theta = self.coefficients_at(w)
        else:
            raise ValueError(
                f"omega must be a scalar or have one value per sample ({u.shape[0]}); got "
                f"shape {w.shape}."
            )
        bound = 1e3 * self.output_scale_ if self.output_scale_ > 0 else np.inf
        yhat, at = free_run(u, theta, self.exponents_, self.ny_, self.nu_, y0=y0, bound=bound)
        if at >= 0:
            wt = float(w) if w.ndim == 0 else float(w[at])
            msg = (
                f"The free run diverged at sample {at} (speed {wt:g} rad/s): |y| exceeded "
                f"{bound:.3g}, 1000 times the largest training output. The identified model "
                "is unstable there; add training speeds near it, lower coef_degree or the "
                "term degree, or raise esr."
            )
            if on_divergence == "raise":
                raise FreeRunDivergenceError(msg)
            warnings.warn(msg, RuntimeWarning, stacklevel=2)
        return yhat

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
    def to_json(self, path=None) -> str:
        """Serialise the fitted model to JSON (see :func:`sknarx.io.model_to_json`)."""
        from ..io import model_to_json

        return model_to_json(self, path)

    @classmethod
    def from_json(cls, source):
        """Rebuild a fitted model from :meth:`to_json` output (a string or a path)."""
        from ..io import model_from_json

        return model_from_json(source)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        return tags
