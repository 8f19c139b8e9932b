"""Speed functions as linear maps of the per-speed coefficients.

Both speed bases are linear in the per-speed coefficient table ``Theta`` (K speeds x
s terms): a least-squares polynomial ``theta(omega) = v(s(omega)) pinv(V) Theta`` and a
natural cubic spline through the K points ``theta(omega) = sum_k l_k(omega) Theta_k``
with cardinal splines ``l_k``. Writing both as one weight matrix ``L(omega)`` (n x K)
lets a single code path propagate the per-speed coefficient covariances to the
coefficient functions, their confidence bands and Monte-Carlo draws, whichever basis
was fitted. The per-speed estimates come from different records, so they are
independent across speeds.
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import Polynomial
from scipy.interpolate import CubicSpline

__all__ = ["speed_weights", "raw_power_map", "propagate_variance", "propagate_covariance"]


def _scaled(omega, a, b):
    return (2.0 * np.asarray(omega, dtype=float) - a - b) / (b - a)


def speed_weights(speeds, omega, basis: str, degree: int) -> np.ndarray:
    """Weights ``L`` (n_omega x K) with ``theta(omega) = L @ Theta``.

    Parameters
    ----------
    speeds : ndarray (K,)
        Training speeds, rad/s.
    omega : array-like (n,)
        Query speeds, rad/s.
    basis : {'polynomial', 'spline'}
    degree : int
        Polynomial degree (ignored for the spline).
    """
    speeds = np.asarray(speeds, dtype=float)
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    K = speeds.size
    a, b = float(speeds.min()), float(speeds.max())
    if K == 1 or a == b:
        return np.ones((omega.size, K)) / K
    if basis == "spline":
        order = np.argsort(speeds)
        eye = np.eye(K)[order]  # value of l_k at each sorted knot
        return CubicSpline(speeds[order], eye, axis=0, bc_type="natural")(omega)
    V = np.polynomial.polynomial.polyvander(_scaled(speeds, a, b), degree)
    v = np.polynomial.polynomial.polyvander(_scaled(omega, a, b), degree)
    return v @ np.linalg.pinv(V)


def raw_power_map(speeds, degree: int) -> np.ndarray:
    """``R`` ((degree+1) x K): raw-power polynomial coefficients ``beta = R @ theta_k``.

    ``beta_j`` multiplies ``omega**j`` (omega in rad/s), as in
    ``SpeedScheduledNarx.speed_polynomials_``.
    """
    speeds = np.asarray(speeds, dtype=float)
    a, b = float(speeds.min()), float(speeds.max())
    V = np.polynomial.polynomial.polyvander(_scaled(speeds, a, b), degree)
    H = np.linalg.pinv(V)  # scaled-basis coefficients from per-speed values
    T = np.zeros((degree + 1, degree + 1))
    for j in range(degree + 1):
        c = Polynomial(np.eye(degree + 1)[j], domain=[a, b]).convert().coef
        T[: c.size, j] = c
    return T @ H


def propagate_variance(L: np.ndarray, var_per_speed: np.ndarray) -> np.ndarray:
    """Variances (n x s) of ``L @ Theta`` from per-speed variances (K x s)."""
    return (L**2) @ var_per_speed


def propagate_covariance(L_row: np.ndarray, cov_per_speed: np.ndarray) -> np.ndarray:
    """Term covariance (s x s) of ``theta(omega)`` at one speed (``L_row``: (K,))."""
    return np.einsum("k,kij->ij", L_row**2, cov_per_speed)
