"""Reading a term (regressor) matrix as it flows between pipeline stages."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

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


def read_term_matrix(X, y, who: str) -> TermMatrix:
    """Term matrix ``X`` (DataFrame with an optional ``speed`` index, or array) and target."""
    if isinstance(X, pd.DataFrame):
        names = [str(c) for c in X.columns]
        speeds = (
            X.index.to_numpy(dtype=float) if X.index.name == "speed" else None
        )
        P = X.to_numpy(dtype=float)
    else:
        P = np.asarray(X, dtype=float)
        if P.ndim == 1:
            raise ValueError(
                f"{who} expects a 2-D term matrix; got a 1-D array. Reshape with "
                "X.reshape(-1, 1) for a single term."
            )
        if P.ndim != 2:
            raise ValueError(f"{who} expects a 2-D term matrix; got {P.ndim} dimensions.")
        names = [f"x{j}" for j in range(P.shape[1])]
        speeds = None
    if P.shape[0] < 1 or P.shape[1] < 1:
        raise ValueError(f"{who}: found array with shape {P.shape}; at least 1 sample and "
                         "1 feature are required.")
    if y is None:
        raise ValueError(f"{who} requires the target output y.")
    y = np.asarray(y, dtype=float).reshape(-1) if np.ndim(y) <= 1 else np.asarray(y, float)
    if y.ndim != 1:
        raise ValueError(f"{who}: y must be 1-D (one output), got shape {np.shape(y)}.")
    if y.shape[0] != P.shape[0]:
        raise ValueError(f"{who}: X has {P.shape[0]} rows but y has {y.shape[0]}.")
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
