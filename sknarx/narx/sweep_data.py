"""The data representation shared by every NARX stage: a sweep of datasets.

A *sweep* is K steady (or transient) records ``(u_k, y_k)`` taken at speeds
``omega_k`` (rad/s). Users hand it over in one of three equivalent forms:

* a list of ``(u, y)`` pairs plus an array of speeds (the paper's view);
* a *long table*: a pandas DataFrame, one row per sample, with columns
  ``speed``, ``u`` and ``y`` (this is also what the simulator writes);
* inside a scikit-learn Pipeline, the long table as ``X`` (plain arrays are read
  positionally as ``(speed, u, y)`` or ``(u, y)``).

Datasets in a long table are the runs of consecutive rows with equal speed, in
order of appearance; sample order inside a run is time order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from sklearn.utils import check_array

__all__ = ["Dataset", "as_datasets", "split_long_table", "check_series"]


@dataclass(frozen=True)
class Dataset:
    """One record at one speed: input ``u`` (N), output ``y`` (m), speed in rad/s."""

    speed: float
    u: np.ndarray
    y: np.ndarray


def check_series(u, y, speed, min_length: int, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Validate one record and return float arrays; errors name the record and the fix."""
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 1 or y.ndim != 1:
        raise ValueError(
            f"{where}: u and y must be 1-D arrays, got shapes {u.shape} and {y.shape}."
        )
    if u.shape[0] != y.shape[0]:
        raise ValueError(
            f"{where}: u has {u.shape[0]} samples but y has {y.shape[0]}; "
            "input and output must be sampled together."
        )
    for name, arr in (("u", u), ("y", y)):
        bad = ~np.isfinite(arr)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"{where}: {name} contains {int(bad.sum())} NaN/inf value(s), first at sample "
                f"{first}; remove or interpolate them before fitting."
            )
    if u.shape[0] < min_length:
        raise ValueError(
            f"{where}: {u.shape[0]} samples are too few; with the chosen lags at least "
            f"{min_length} are needed (lags + one more sample per regressor)."
        )
    if speed is not None and not np.isfinite(speed):
        raise ValueError(f"{where}: speed is {speed}; speeds must be finite (rad/s).")
    return u, y


def split_long_table(df: pd.DataFrame, require_y: bool = True) -> list[Dataset]:
    """Split a long table with columns ``speed``, ``u`` and ``y`` into datasets."""
    missing = [c for c in ("speed", "u") + (("y",) if require_y else ()) if c not in df.columns]
    if missing:
        raise ValueError(
            f"The long table lacks column(s) {missing}; expected one row per sample with "
            "columns 'speed' (rad/s), 'u' (input) and 'y' (output)."
        )
    speed = df["speed"].to_numpy(dtype=float)
    if not np.all(np.isfinite(speed)):
        raise ValueError("Column 'speed' contains NaN/inf; every sample needs its speed (rad/s).")
    u = df["u"].to_numpy(dtype=float)
    y = df["y"].to_numpy(dtype=float) if "y" in df.columns else np.full(len(df), np.nan)
    return [Dataset(float(speed[a]), u[a:b], y[a:b]) for a, b in runs(speed)]


def runs(values: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges of consecutive equal values."""
    values = np.asarray(values)
    if values.size == 0:
        return []
    cut = np.flatnonzero(values[1:] != values[:-1]) + 1
    edges = np.concatenate([[0], cut, [values.size]])
    return list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))


def as_datasets(datasets, speeds=None) -> list[Dataset]:
    """Normalise the accepted sweep forms into a list of :class:`Dataset`."""
    if isinstance(datasets, pd.DataFrame):
        if speeds is not None:
            raise ValueError(
                "Pass either a long DataFrame (with a 'speed' column) or a list of (u, y) "
                "pairs with speeds, not both."
            )
        return split_long_table(datasets)
    if isinstance(datasets, tuple) and len(datasets) == 2 and np.ndim(datasets[0]) == 1:
        datasets = [datasets]
    try:
        pairs = list(datasets)
    except TypeError as exc:
        raise TypeError(
            "datasets must be a list of (u, y) pairs or a long DataFrame with columns "
            "'speed', 'u', 'y'."
        ) from exc
    if speeds is None:
        raise ValueError(
            "speeds (rad/s), one per dataset, are required with a list of (u, y) pairs."
        )
    speeds = np.atleast_1d(np.asarray(speeds, dtype=float))
    if speeds.ndim != 1 or speeds.shape[0] != len(pairs):
        raise ValueError(
            f"Got {len(pairs)} datasets but {speeds.size} speeds; give one speed per dataset."
        )
    out = []
    for k, (pair, w) in enumerate(zip(pairs, speeds, strict=True)):
        if len(pair) != 2:
            raise ValueError(f"Dataset {k} is not a (u, y) pair.")
        out.append(Dataset(float(w), np.asarray(pair[0]), np.asarray(pair[1])))
    return out


def read_sample_table(X, y=None, require_y: bool = True) -> tuple[list[Dataset], bool]:
    """Read the pipeline's ``X``: a long table of samples.

    Returns the datasets and whether speeds were given. A DataFrame needs
    columns ``u`` and ``y`` (``y`` may instead come from the target) and may have
    ``speed``; a 2-D array is read as ``(speed, u, y)`` with three columns or
    ``(u, y)`` with two.
    """
    if isinstance(X, pd.DataFrame):
        df = X
        if "y" not in df.columns and y is not None:
            df = df.assign(y=np.asarray(y, dtype=float))
        has_speed = "speed" in df.columns
        if not has_speed:
            df = df.assign(speed=0.0)
        if "u" not in df.columns:
            raise ValueError(
                "X must have a column 'u' (input) and 'y' (output), optionally 'speed' (rad/s); "
                f"got columns {list(X.columns)}."
            )
        return split_long_table(df, require_y=require_y), has_speed
    arr = check_array(X, dtype=np.float64, ensure_all_finite=False)
    if arr.shape[1] not in (2, 3):
        raise ValueError(
            "X must be a long table: a DataFrame with columns 'speed', 'u', 'y', or a 2-D "
            f"array with columns (speed, u, y) or (u, y); got {arr.shape[1]} feature(s) "
            f"(n_features = {arr.shape[1]})."
        )
    if arr.shape[1] == 3:
        cols = {"speed": arr[:, 0], "u": arr[:, 1], "y": arr[:, 2]}
        has_speed = True
    else:
        cols = {"speed": np.zeros(arr.shape[0]), "u": arr[:, 0], "y": arr[:, 1]}
        has_speed = False
    return split_long_table(pd.DataFrame(cols), require_y=require_y), has_speed
