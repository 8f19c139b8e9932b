"""The speed functions of :class:`~sknarx.narx.SpeedScheduledNarx`: coefficients as
functions of the speed (rad/s).

A global polynomial of degree ``coef_degree`` in the scaled speed
``s = (2 omega - a - b) / (b - a)`` fitted by least squares to the per-speed
coefficients (the paper), or a natural cubic spline through them; with
``refine='output_error'`` the polynomials are refined on the free run of every speed
at once. Also the coefficients and their standard errors at any speed.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from numpy.polynomial import Polynomial

from .._progress import phase
from ._output_error import refine_speed_functions
from ._speed_map import raw_power_map, speed_weights

__all__ = ["SpeedExtrapolationWarning", "coefficient_std", "coefficients_at",
           "fit_speed_polynomials", "refine_speed_functions_of", "set_speed_polynomials"]


class SpeedExtrapolationWarning(UserWarning):
    """A requested speed lies outside the range of the fitted speeds."""


def _spline(speeds, coef):
    from scipy.interpolate import CubicSpline

    order = np.argsort(speeds)
    return CubicSpline(np.asarray(speeds)[order], np.asarray(coef)[order], axis=0,
                       bc_type="natural")



def refine_speed_functions_of(est, fitted):
    """The speed polynomials that minimise the free-run error of every speed's
    records at once (each speed weighted by its simulation-error variance), with
    their joint covariance ``coef_poly_cov_``."""
    a, b = est.speed_range_
    J = est.coef_degree_
    s = (2.0 * np.asarray(fitted.speeds) - a - b) / (b - a)
    basis = s[:, None] ** np.arange(J + 1)
    with phase("output-error refinement of the speed functions"):
        try:
            fit = refine_speed_functions(fitted.records, basis, est.coef_poly_,
                                         est.exponents_, est.ny_, est.nu_,
                                         np.asarray(fitted.sigma2, dtype=float),
                                         bound=est._bound())
        except FloatingPointError:
            warnings.warn(
                "refine='output_error': the speed polynomials through the refined "
                "per-speed coefficients make a training record's free run diverge, so "
                "they are kept as fitted (least squares over the speeds); consider "
                "speed_basis='spline'.", RuntimeWarning, stacklevel=3)
            return
    set_speed_polynomials(est, fit.theta, fit.cov)


def set_speed_polynomials(est, beta, cov):
    """Speed polynomials ``beta`` (in the scaled speed) refined elsewhere, with their
    joint covariance: the scaled form, the raw form and its standard errors."""
    a, b = est.speed_range_
    J = beta.shape[1] - 1
    est.coef_poly_ = np.asarray(beta, dtype=float)
    est.coef_poly_cov_ = np.asarray(cov, dtype=float)
    # the same polynomials in powers of omega (rad/s): linear in the scaled ones
    R = np.array([np.pad(c := Polynomial(np.eye(J + 1)[i], domain=[a, b]).convert().coef,
                         (0, J + 1 - c.size)) for i in range(J + 1)])
    names = est.selected_terms_
    cols = [f"beta{j}" for j in range(J + 1)]
    est.speed_polynomials_ = pd.DataFrame(est.coef_poly_ @ R, index=names, columns=cols)
    blocks = est.coef_poly_cov_.reshape(len(names), J + 1, len(names), J + 1)
    se = np.array([np.sqrt(np.clip(np.diag(R.T @ blocks[m, :, m, :] @ R), 0, None))
                   for m in range(len(names))])
    est.speed_polynomials_std_err_ = pd.DataFrame(se, index=names, columns=cols)


def fit_speed_polynomials(est, coef, speeds):
    names = est.selected_terms_
    if speeds is None:
        # No speeds: one operating point, constant coefficients.
        est.speed_range_ = None
        est.coef_poly_ = coef[:1].T.copy()
        est.speed_polynomials_ = pd.DataFrame(est.coef_poly_, index=names, columns=["beta0"])
        est.speed_polynomials_std_err_ = pd.DataFrame(
            est.coef_std_err_per_speed_.to_numpy()[:1].T, index=names, columns=["beta0"])
        return
    a, b = float(np.min(speeds)), float(np.max(speeds))
    est.speed_range_ = (a, b)
    est.coef_spline_ = None
    if est.speed_basis == "spline":
        est.coef_spline_ = _spline(speeds, coef)
    J = est.coef_degree_
    if a == b:  # a single speed (then coef_degree is 0): constant coefficients
        est.coef_poly_ = coef[:1].T.copy()
        est.speed_polynomials_ = pd.DataFrame(est.coef_poly_, index=names,
                                               columns=["beta0"])
        est.speed_polynomials_std_err_ = pd.DataFrame(
            est.coef_std_err_per_speed_.to_numpy()[:1].T, index=names, columns=["beta0"])
        return
    polys = [Polynomial.fit(speeds, coef[:, m], J, domain=[a, b]) for m in range(coef.shape[1])]
    est.coef_poly_ = np.array([np.pad(p.coef, (0, J + 1 - p.coef.size)) for p in polys])
    raw_coefs = [p.convert().coef for p in polys]  # powers of omega in rad/s
    raw = np.array([np.pad(c, (0, J + 1 - c.size)) for c in raw_coefs])
    est.speed_polynomials_ = pd.DataFrame(
        raw, index=names, columns=[f"beta{j}" for j in range(J + 1)]
    )
    var = est.coef_std_err_per_speed_.to_numpy() ** 2
    est.speed_polynomials_std_err_ = pd.DataFrame(
        np.sqrt(raw_power_map(speeds, J) ** 2 @ var).T, index=names,
        columns=[f"beta{j}" for j in range(J + 1)]
    )

# ------------------------------------------------------------ evaluate


def coefficient_std(est, omega):
    if est.coef_cov_per_speed_ is None:
        raise ValueError(
            "This model carries no coefficient covariance (it was read from a format-1 "
            "model file); refit it to get standard errors."
        )
    w = np.asarray(omega, dtype=float)
    C = getattr(est, "coef_poly_cov_", None)
    if C is not None:  # speed functions refined jointly: their own covariance
        a, b = est.speed_range_
        J = est.coef_poly_.shape[1]
        V = (((2.0 * w.reshape(-1) - a - b) / (b - a))[:, None]) ** np.arange(J)
        m = est.coef_poly_.shape[0]
        blocks = C.reshape(m, J, m, J)
        var = np.stack([np.einsum("nj,jk,nk->n", V, blocks[i, :, i, :], V)
                        for i in range(m)], axis=1)
        return np.sqrt(np.clip(var, 0.0, None)).reshape(w.shape + (m,))
    var = est.coef_std_err_per_speed_.to_numpy() ** 2
    if est.speed_range_ is None:
        return np.array(np.broadcast_to(np.sqrt(var[0]), w.shape + (var.shape[1],)))
    L = speed_weights(est.speeds_, w.reshape(-1), est.speed_basis, est.coef_degree_)
    return np.sqrt(L**2 @ var).reshape(w.shape + (var.shape[1],))


def coefficients_at(est, omega):
    w = np.asarray(omega, dtype=float)
    if est.speed_range_ is None:
        out = np.broadcast_to(est.coef_poly_[:, 0], w.shape + (est.coef_poly_.shape[0],))
        return np.array(out)
    if not np.all(np.isfinite(w)):
        raise ValueError("omega must be finite (rad/s).")
    a, b = est.speed_range_
    if np.any((w < a) | (w > b)):
        lo, hi = float(np.min(w)), float(np.max(w))
        warnings.warn(
            f"Speed(s) {lo:g}..{hi:g} rad/s lie outside the fitted range {a:g}..{b:g} "
            "rad/s; the coefficient polynomials are extrapolated and the model may be "
            "inaccurate or unstable there.",
            SpeedExtrapolationWarning,
            stacklevel=3,
        )
    if getattr(est, "coef_spline_", None) is not None:
        return est.coef_spline_(w)
    s = (2.0 * w - a - b) / (b - a) if b > a else np.zeros_like(w)
    return np.moveaxis(np.polynomial.polynomial.polyval(s, est.coef_poly_.T), 0, -1)
