"""The no-gap floor: what measurement noise alone leaves of the held-out gap.

Each held-out feature carries its measured standard error. Were the calibrated model
exact, the measurement would be the model's features plus noise at those errors: the
comparison is repeated on such draws, with every tolerance as it is, and the held-out
excess per feature they leave is the noise's. Its ``1 - false_alarm`` quantile is the
no-gap floor (a sweep within it cannot be told from noise at that level) and its
median is the noise no candidate can remove. Both come from the sweep's own noise and
the rule's stated false-alarm level; nothing is fitted on trials.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..orders import is_nonsync
from .candidate import NoiseFloor
from .gapmap import comparison_layout, excess_of_residual, fast_residual

__all__ = ["noise_floor", "sweep_noise_floor"]


def noise_floor(excess_of, model, se, noisy, false_alarm: float, n_draws: int,
                seed: int) -> NoiseFloor:
    """The noise floor of a comparison.

    Parameters
    ----------
    excess_of : callable
        ``excess_of(measured) -> excess per feature``: the comparison of a measured
        vector (complex, one per feature) with the model, every tolerance as in the
        diagnosis.
    model : ndarray of complex
        The calibrated model's features.
    se : ndarray
        Each feature's measured standard error (per real and imaginary part).
    noisy : ndarray of bool
        The features that carry Gaussian noise (order vectors); the others (line
        energies above a white floor, zero under noise alone) keep the model's value.
    false_alarm : float
        The floor's upper-tail probability.
    n_draws : int
        At least this many draws; more where fewer than 20 would lie beyond the floor.
    seed : int

    Returns
    -------
    NoiseFloor
        The ``1 - false_alarm`` quantile of the draws' held-out excess per feature and
        their median.

    Examples
    --------
    >>> import numpy as np
    >>> S = np.ones(200, complex)
    >>> def excess(M):  # chi-square with two degrees of freedom, less its mean
    ...     return np.clip(np.abs(M - S) ** 2 - 2, 0, None)
    >>> f = noise_floor(excess, S, np.ones(200), np.ones(200, bool), 0.01, 200, 0)
    >>> 0.6 < f.median < 0.9 < f.floor < 1.2   # the mean is 2/e = 0.74
    True
    """
    rng = np.random.default_rng(seed)
    n_draws = max(int(n_draws), int(np.ceil(20.0 / false_alarm)))
    model = np.asarray(model, dtype=complex)
    se = np.where(noisy, np.asarray(se, dtype=float), 0.0)
    draws = np.empty(n_draws)
    for i in range(n_draws):
        noise = se * (rng.standard_normal(se.size) + 1j * rng.standard_normal(se.size))
        draws[i] = float(np.mean(excess_of(model + noise)))
    return NoiseFloor(floor=float(np.quantile(draws, 1.0 - false_alarm)),
                      median=float(np.median(draws)), n_draws=n_draws,
                      false_alarm=float(false_alarm))


def sweep_noise_floor(meas: pd.DataFrame, sim: pd.DataFrame, rule, n_draws: int,
                      seed: int) -> NoiseFloor:
    """:func:`noise_floor` of a time-series comparison (:func:`sknarx.gap.compare`):
    ``meas`` the held-out measured features with their tolerances, ``sim`` the
    calibrated model's features at the same speeds."""
    layout = comparison_layout(meas, sim, rule)
    S = layout["S"]
    noisy = ~np.array([is_nonsync(k[3]) for k in layout["index"]], dtype=bool)

    def excess_of(M):
        return excess_of_residual(fast_residual(M, S, **layout["kwargs"]), layout)

    return noise_floor(excess_of, S, layout["kwargs"]["se_m"], noisy, rule.false_alarm,
                       n_draws, seed)
