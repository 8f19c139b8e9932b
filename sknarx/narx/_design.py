"""Reading a term (regressor) matrix as it flows between pipeline stages."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from sklearn.utils.validation import validate_data

from .sweep_data import runs


@dataclass
class TermMatrix:
    P: np.ndarray  # (n_samples, n_terms), all-NaN rows = no history
    y: np.ndarray  # (n_samples,)
    names: list[str]
    speeds: np.ndarray | None  # per-sample speed (rad/s) or None
    groups: list[tuple[int, int]]  # dataset row ranges

    def dataset_speeds(self) -> np.ndarray | None:
        if self.speeds is None:
            return None
        return np.array([self.speeds[a] for a, _ in self.groups])

    def valid_rows(self, a: int, b: int) -> np.ndarray:
        return ~np.all(np.isnan(self.P[a:b]), axis=1)


def read_term_matrix(estimator, X, y, who: str, reset: bool = True) -> TermMatrix:
    """Term matrix ``X`` (DataFrame with an optional ``speed`` index, or array) and target.

    Validation goes through scikit-learn's ``validate_data`` (shapes, dtypes,
    sparse and complex input, feature names); whole NaN rows are allowed because
    they mark samples without lag history.
    """
    speeds = None
    if isinstance(X, pd.DataFrame) and X.index.name == "speed":
        speeds = X.index.to_numpy(dtype=float)
    names = [str(c) for c in X.columns] if isinstance(X, pd.DataFrame) else None
    if y is None:
        raise ValueError(
            f"{who} requires y to be passed, but the target y is None: give the output."
        )
    P, y = validate_data(estimator, X, y, reset=reset, ensure_all_finite="allow-nan",
                         y_numeric=True, dtype=np.float64)
    if names is None:
        names = [f"x{j}" for j in range(P.shape[1])]
    nan_rows = np.all(np.isnan(P), axis=1)
    bad = ~np.isfinite(P) & ~nan_rows[:, None]
    if bad.any():
        r = int(np.flatnonzero(bad.any(axis=1))[0])
        raise ValueError(
            f"{who}: X contains NaN or inf (first in row {r}); only whole rows may be NaN "
            "(samples without lag history). Clean the input data."
        )
    if not np.all(np.isfinite(y[~nan_rows])):
        raise ValueError(f"{who}: y contains NaN or inf; clean the output data.")
    if speeds is not None and not np.all(np.isfinite(speeds)):
        raise ValueError(f"{who}: the speed index contains NaN/inf.")
    groups = runs(speeds) if speeds is not None else [(0, P.shape[0])]
    return TermMatrix(P=P, y=y, names=names, speeds=speeds, groups=groups)


def check_nan_rows(P: np.ndarray) -> np.ndarray:
    """Reject NaN/inf except whole NaN rows (samples without history)."""
    nan_rows = np.all(np.isnan(P), axis=1)
    if (~np.isfinite(P) & ~nan_rows[:, None]).any():
        raise ValueError(
            "Input X contains NaN or infinity outside whole rows; only samples without lag "
            "history may be all-NaN. Clean the input data."
        )
    return P


def as_configured_output(estimator, frame: pd.DataFrame):
    """The transform's DataFrame, or its plain array under ``set_output(transform="default")``.

    Unconfigured, the stages pass DataFrames whose ``speed`` index tells the next stage
    where each dataset begins; a user who asks for scikit-learn's default container gets
    a float array (and with it one dataset: the speeds are not in an array).
    """
    config = getattr(estimator, "_sklearn_output_config", {})
    if config.get("transform") == "default":
        return frame.to_numpy()
    return frame
