"""Cross-validation over operating speeds."""

from __future__ import annotations

import numpy as np
from sklearn.model_selection import BaseCrossValidator

__all__ = ["LeaveOneSpeedOut"]


class LeaveOneSpeedOut(BaseCrossValidator):
    """Hold out one speed at a time; by default only speeds inside the training range.

    Unlike ``LeaveOneGroupOut``, the lowest and highest speeds are not held out
    when ``interior=True``: predicting them would be extrapolation of the
    coefficient functions, which measures something else.

    Parameters
    ----------
    interior : bool, default=True
        Skip the extreme speeds as test folds (they always stay in training).

    Examples
    --------
    >>> import numpy as np
    >>> from sknarx.narx.splitters import LeaveOneSpeedOut
    >>> speeds = np.repeat([100.0, 150.0, 200.0, 250.0], 3)
    >>> [np.unique(speeds[test]).tolist() for _, test in LeaveOneSpeedOut().split(speeds,
    ...                                                                            groups=speeds)]
    [[150.0], [200.0]]
    """

    def __init__(self, interior=True):
        self.interior = interior

    def _speeds(self, X, groups):
        if groups is not None:
            return np.asarray(groups, dtype=float)
        if hasattr(X, "columns") and "speed" in X.columns:
            return X["speed"].to_numpy(dtype=float)
        raise ValueError("LeaveOneSpeedOut needs groups=speeds or X with a 'speed' column.")

    def _iter_test_masks(self, X=None, y=None, groups=None):
        speeds = self._speeds(X, groups)
        uniq = np.unique(speeds)
        if self.interior:
            uniq = uniq[1:-1]
        for w in uniq:
            yield speeds == w

    def get_n_splits(self, X=None, y=None, groups=None):
        """Number of folds: one per held-out speed (interior speeds only by default)."""
        speeds = self._speeds(X, groups)
        n = np.unique(speeds).size
        return max(n - 2, 0) if self.interior else n
