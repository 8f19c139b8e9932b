"""Monte-Carlo prediction bands of a speed-scheduled model's free run.

Each draw takes every training speed's coefficients from their estimated normal
distribution (or, for speed functions refined on the free run, the speed polynomials
from theirs), maps them through the speed basis exactly as the fit does, and
free-runs the model; the band is the pointwise quantiles of the draws that stayed
bounded, and the share that diverged is reported.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from numbers import Integral

import numpy as np
from sklearn.utils import check_random_state

from ._speed_functions import coefficient_std
from ._speed_map import speed_weights
from .freerun import free_run
from .terms import split_noise_terms

__all__ = ["SimulationInterval", "simulate_interval"]


def _sqrt_psd(C):
    """A factor ``F`` with ``F F^T = C`` for a covariance that may be singular."""
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    return V * np.sqrt(np.clip(lam, 0.0, None))


@dataclass
class SimulationInterval:
    """Monte-Carlo prediction band of a free run (see :meth:`SpeedScheduledNarx.simulate_interval`).

    Attributes
    ----------
    y : ndarray (n_samples,)
        Free run with the fitted coefficients (NaN after a divergence).
    lower, upper : ndarray (n_samples,)
        Pointwise ``(1 - level)/2`` and ``(1 + level)/2`` quantiles over the draws that
        stayed bounded (NaN where none did).
    level : float
    n_draws : int
    diverged_fraction : float
        Share of the coefficient draws whose free run diverged: a model close to
        instability at this speed shows it here before its nominal run does.
    """

    y: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    level: float
    n_draws: int
    diverged_fraction: float



def simulate_interval(est, u, omega, y0=None, n_draws=200, level=0.95,
                      random_state=None):
    """The Monte-Carlo band of :meth:`SpeedScheduledNarx.simulate_interval`."""
    u, w = est._check_run(u, omega)
    if not (isinstance(n_draws, Integral) and n_draws >= 1):
        raise ValueError(f"n_draws must be a positive integer, got {n_draws!r}.")
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level!r}.")
    if est.coef_cov_per_speed_ is None:
        coefficient_std(est, 0.0)  # raises the no-covariance error
    rng = check_random_state(random_state)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        y_nominal = est.simulate(u, float(w) if w.ndim == 0 else w, y0=y0,
                                  on_divergence="warn")
    process = split_noise_terms(est.selected_terms_)[0]
    uniq, inv = np.unique(np.atleast_1d(w), return_inverse=True)
    if est.speed_range_ is None:
        L = np.ones((uniq.size, 1))
    else:
        L = speed_weights(est.speeds_, uniq, est.speed_basis, est.coef_degree_)
    Theta = est.coef_per_speed_.to_numpy()
    chol = [_sqrt_psd(C) for C in est.coef_cov_per_speed_]
    C_poly = getattr(est, "coef_poly_cov_", None)
    if C_poly is not None:  # speed functions refined jointly: draw them
        a, b = est.speed_range_
        s_uniq = (2.0 * uniq - a - b) / (b - a)
        F_poly = _sqrt_psd(C_poly)
    runs = np.full((n_draws, u.size), np.nan)
    diverged = 0
    for d in range(n_draws):
        if C_poly is not None:
            beta = est.coef_poly_ + (F_poly @ rng.standard_normal(C_poly.shape[0])
                                      ).reshape(est.coef_poly_.shape)
            theta = np.polynomial.polynomial.polyval(s_uniq, beta.T).T
            theta = np.atleast_2d(theta)[:, process]
        else:
            draw = np.stack([t + c @ rng.standard_normal(t.size)
                             for t, c in zip(Theta, chol, strict=True)])
            theta = (L @ draw)[:, process]
        theta = theta if w.ndim == 0 else theta[inv]
        y, at = free_run(u, theta, est.exponents_, est.ny_, est.nu_, y0=y0,
                         bound=est._bound())
        if at >= 0:
            diverged += 1
        else:
            runs[d] = y
    q = [(1 - level) / 2, (1 + level) / 2]
    if diverged == n_draws:
        warnings.warn(f"All {n_draws} coefficient draws diverged; the band is NaN.",
                      RuntimeWarning, stacklevel=2)
        lower = upper = np.full(u.size, np.nan)
    else:
        lower, upper = np.nanquantile(runs, q, axis=0)
    return SimulationInterval(y=y_nominal, lower=lower, upper=upper, level=float(level),
                              n_draws=int(n_draws), diverged_fraction=diverged / n_draws)
