"""NarxTermDictionary: the candidate polynomial NARX terms as a scikit-learn transformer."""

from __future__ import annotations

from numbers import Integral

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted

from ._design import as_configured_output
from ._els import innovations, lagged
from .sweep_data import check_series, read_sample_table
from .terms import TermSet, monomial_exponents, n_candidate_terms, noise_term_name, term_names

__all__ = ["NarxTermDictionary"]


class NarxTermDictionary(TransformerMixin, BaseEstimator):
    """All polynomial NARX candidate terms of lagged input and output.

    The terms are every product of at most ``degree`` factors drawn from
    ``y(t-1), ..., y(t-ny), u(t-1), ..., u(t-nu)``, plus the constant: the
    paper's ``M = (n + L)! / (n! L!)`` candidates with ``n = ny + nu``.

    Parameters
    ----------
    ny : int, default=3
        Largest output lag.
    nu : int, default=3
        Largest input lag.
    degree : int, default=3
        Largest total degree of a term.
    noise_lags : int, default=0
        Also offer the NARMAX noise terms ``e(t-1) .. e(t-noise_lags)``: lagged
        innovations of each record, estimated by a long linear ARX (Hannan &
        Rissanen's first stage) on the record being transformed — they need the
        output, like every lagged-``y`` term. A downstream
        :class:`SpeedScheduledNarx` iterates them into prediction errors of the
        fitted model (extended least squares). ``0``: plain NARX terms.

    Attributes
    ----------
    exponents_ : ndarray of shape (n_terms_, ny + nu)
        Exponent of each lagged variable (columns ``y(t-1..ny)``, ``u(t-1..nu)``)
        in each term (rows).
    n_terms_ : int
        Number of candidate terms ``M`` (noise terms included).
    innovation_order_ : int
        Order of the long ARX that estimates the innovations (0 without noise terms).
    max_lag_ : int
        ``max(ny, nu)``: the first ``max_lag_`` samples of each dataset have no
        complete history.
    n_features_in_ : int
        Number of columns of ``X`` seen in :meth:`fit`.
    feature_names_in_ : ndarray of str
        Column names of ``X`` when it is a DataFrame.

    Notes
    -----
    ``X`` is the *long sample table* (see ``docs/architecture.md``): one row per
    sample with columns ``speed`` (rad/s), ``u`` and ``y``; a 2-D array is read as
    ``(speed, u, y)`` or ``(u, y)``. The output of :meth:`transform` is a
    DataFrame with one column per term, named as in :meth:`get_feature_names_out`,
    and, when speeds are known, an index named ``speed`` that tells the
    downstream selector and regressor which rows belong to which dataset. Rows
    without a complete history (the first ``max_lag_`` samples of each dataset)
    are all-NaN so every stage drops exactly the same rows.

    Examples
    --------
    >>> import numpy as np
    >>> from sknarx import NarxTermDictionary
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(50); y = np.convolve(u, [0, 0.5, 0.2])[:50]
    >>> X = np.column_stack([u, y])
    >>> d = NarxTermDictionary(ny=1, nu=2, degree=2).fit(X)
    >>> d.n_terms_
    10
    >>> list(d.get_feature_names_out()[:5])
    ['1', 'y(t-1)', 'u(t-1)', 'u(t-2)', 'y(t-1)^2']
    >>> d.transform(X).shape
    (50, 10)
    """

    _parameter_constraints = {
        "ny": [Interval(Integral, 0, None, closed="left")],
        "nu": [Interval(Integral, 0, None, closed="left")],
        "degree": [Interval(Integral, 0, None, closed="left")],
        "noise_lags": [Interval(Integral, 0, None, closed="left")],
    }

    def __init__(self, ny=3, nu=3, degree=3, noise_lags=0):
        self.ny = ny
        self.nu = nu
        self.degree = degree
        self.noise_lags = noise_lags

    def fit(self, X, y=None):
        """Enumerate the terms and check ``X``.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, 2 or 3)
            Long sample table: ``speed`` (rad/s), ``u``, ``y``.
        y : array-like of shape (n_samples,), optional
            The output, used when ``X`` has no ``y`` column.

        Returns
        -------
        self : NarxTermDictionary
        """
        self._validate_params()
        if self.ny + self.nu == 0 and self.degree > 0:
            raise ValueError("ny + nu must be at least 1 to build lagged terms.")
        self._read(X, y, record=True)
        self.exponents_ = monomial_exponents(self.ny, self.nu, self.degree)
        self.n_terms_ = n_candidate_terms(self.ny, self.nu, self.degree) + self.noise_lags
        self.max_lag_ = max(self.ny, self.nu)
        # A long ARX approximates the inverse noise filter; a few times the longest lag
        # (at least 10) is the usual first-stage choice.
        self.innovation_order_ = (max(10, 4 * max(self.ny, self.nu, self.noise_lags))
                                  if self.noise_lags else 0)
        self.termset_ = TermSet(self.exponents_, self.ny, self.nu)
        return self

    def _read(self, X, y, record=False):
        datasets, has_speed = read_sample_table(X, y)
        if record:
            if isinstance(X, pd.DataFrame):
                self.feature_names_in_ = np.asarray(X.columns, dtype=object)
                self.n_features_in_ = X.shape[1]
            else:
                self.n_features_in_ = np.asarray(X).shape[1]
        elif X is not None and not isinstance(X, pd.DataFrame):
            if np.asarray(X).shape[1] != self.n_features_in_:
                raise ValueError(
                    f"X has {np.asarray(X).shape[1]} features, but NarxTermDictionary is "
                    f"expecting {self.n_features_in_} features as input."
                )
        # Any length is accepted: samples without a complete history become NaN rows and
        # the selector/regressor say so if too few rows remain.
        for k, d in enumerate(datasets):
            check_series(d.u, d.y, d.speed, 1, f"Dataset {k} (speed {d.speed:g} rad/s)")
        return datasets, has_speed

    def transform(self, X, y=None):
        """Candidate regressor matrix of the long sample table ``X``.

        Parameters
        ----------
        X : DataFrame or array-like of shape (n_samples, 2 or 3)
        y : ignored unless ``X`` lacks the ``y`` column.

        Returns
        -------
        P : DataFrame of shape (n_samples, n_terms_)
            Columns named by :meth:`get_feature_names_out`; index named ``speed``
            when speeds are known; all-NaN rows where the history is incomplete.
            A plain array after ``set_output(transform="default")``.
        """
        check_is_fitted(self, "exponents_")
        datasets, has_speed = self._read(X, y)
        blocks, speeds = [], []
        lag = self.max_lag_
        n_process = self.n_terms_ - self.noise_lags
        for d in datasets:
            P = np.full((len(d.y), self.n_terms_), np.nan)
            if len(d.y) > lag:
                P[lag:, :n_process] = self.termset_.evaluate(d.u, d.y, lag, len(d.y))
                if self.noise_lags:
                    e = innovations(d.u, d.y, self.innovation_order_)
                    P[lag:, n_process:] = lagged(e, range(1, self.noise_lags + 1))[lag:]
            blocks.append(P)
            speeds.append(np.full(len(d.y), d.speed))
        P = np.vstack(blocks)
        index = pd.Index(np.concatenate(speeds), name="speed") if has_speed else None
        frame = pd.DataFrame(P, columns=self.get_feature_names_out(), index=index)
        return as_configured_output(self, frame)

    def get_feature_names_out(self, input_features=None):
        """Term names: ``1``, ``y(t-1)``, ``u(t-2)^2``, ``y(t-1)*u(t-3)``, ...

        Parameters
        ----------
        input_features : ignored

        Returns
        -------
        names : ndarray of str
        """
        check_is_fitted(self, "exponents_")
        names = term_names(self.exponents_, self.ny, self.nu)
        names += [noise_term_name(k) for k in range(1, self.noise_lags + 1)]
        return np.asarray(names, dtype=object)

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = False
        # The output is always a float64 DataFrame of monomials.
        tags.transformer_tags.preserves_dtype = []
        return tags
