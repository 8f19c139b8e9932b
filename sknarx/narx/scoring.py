"""Free-run scoring for cross-validation over held-out speeds."""

from __future__ import annotations

import warnings

import numpy as np

from .freerun import FreeRunDivergenceError
from .sweep_data import read_sample_table

__all__ = ["nrmse", "free_run_nrmse", "free_run_scorer", "DIVERGENCE_NRMSE",
           "FreeRunDivergenceWarning"]

#: NRMSE a diverging free run scores: finite, so a grid search can still rank the
#: other settings and average over folds, and far worse than any model that stays
#: bounded (a constant zero prediction scores 1).
DIVERGENCE_NRMSE = 1e3


class FreeRunDivergenceWarning(RuntimeWarning):
    """A free run diverged while scoring; it scored ``DIVERGENCE_NRMSE``."""


def nrmse(y_true, y_pred) -> float:
    """Root-mean-square error normalised by the standard deviation of ``y_true``."""
    y_true = np.asarray(y_true, dtype=float)
    y_pred = np.asarray(y_pred, dtype=float)
    sd = np.std(y_true)
    if sd == 0:
        return float(np.sqrt(np.mean((y_true - y_pred) ** 2)))
    return float(np.sqrt(np.mean((y_true - y_pred) ** 2)) / sd)


def _final_step(estimator):
    return estimator[-1] if hasattr(estimator, "steps") else estimator


def free_run_nrmse(estimator, X, y=None, discard=0) -> float:
    """Mean free-run NRMSE over the datasets of the long sample table ``X``.

    Each dataset is simulated from its input alone at its own speed, started
    from its first measured outputs (model predicted output), and the first
    ``discard`` samples are left out of the error. A diverging free run scores
    ``DIVERGENCE_NRMSE`` (1000, finite so that a grid search still ranks the other
    settings) and warns with :class:`FreeRunDivergenceWarning`.
    """
    model = _final_step(estimator)
    datasets, has_speed = read_sample_table(X, y)
    errors = []
    for d in datasets:
        lag = max(model.ny_, model.nu_)
        try:
            yhat = model.simulate(d.u, d.speed if has_speed else 0.0, y0=d.y[:lag])
        except FreeRunDivergenceError as exc:
            warnings.warn(f"{exc} Scored as NRMSE {DIVERGENCE_NRMSE:g}.",
                          FreeRunDivergenceWarning, stacklevel=2)
            errors.append(DIVERGENCE_NRMSE)
            continue
        errors.append(min(nrmse(d.y[discard:], yhat[discard:]), DIVERGENCE_NRMSE))
    return float(np.mean(errors))


def free_run_scorer(estimator, X, y=None):
    """scikit-learn scorer: minus the mean free-run NRMSE (greater is better).

    Use as ``cross_validate(pipe, X, y, groups=X['speed'], cv=LeaveOneGroupOut(),
    scoring=free_run_scorer)``; ``X`` is the long sample table (``speed``, ``u``, ``y``).
    """
    return -free_run_nrmse(estimator, X, y)
