"""What a fit removed, where, and how sure: shares of the held-out gap and their bootstraps.

Every function reads comparison tables of held-out features (one row per ``speed``,
``window``, ``channel``, ``feature``, with ``excess``: see :func:`sknarx.gap.compare`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["alternating_split", "log_shrink", "bootstrap_shrink", "setting_support",
           "table_evidence", "regions_after"]

_KEY = ["speed", "window", "channel", "feature"]


def alternating_split(n: int, block: int = 1) -> np.ndarray:
    """Training mask of ``n`` speed-ordered units: alternating blocks of ``block`` units,
    the first for training, and the last unit always for training, so that every
    held-out unit lies between training ones (a fit is judged where it interpolates).

    Examples
    --------
    >>> alternating_split(6).astype(int).tolist()
    [1, 0, 1, 0, 1, 1]
    >>> alternating_split(7, block=2).astype(int).tolist()
    [1, 1, 0, 0, 1, 1, 1]
    """
    train = (np.arange(n) // block) % 2 == 0
    if n:
        train[-1] = True
    return train


def log_shrink(cmp_before: pd.DataFrame, cmp_after: pd.DataFrame | None) -> float:
    """Share of ``sum(log(1 + excess))`` a fit removed: the breadth of its gain (the
    excess is dominated by its largest features; its logarithm is not). ``-inf`` for a
    fit without a table (it diverged).

    Examples
    --------
    >>> import pandas as pd
    >>> before = pd.DataFrame({"speed": [1, 2], "window": "steady", "channel": "x",
    ...                        "feature": "1x", "excess": [3.0, 3.0]})
    >>> round(log_shrink(before, before.assign(excess=[0.0, 3.0])), 3)
    0.5
    """
    if cmp_after is None:
        return -np.inf
    b = cmp_before.set_index(_KEY)["excess"]
    a = cmp_after.set_index(_KEY)["excess"].reindex(b.index).fillna(0.0)
    lb = np.log1p(b).sum()
    return float(1.0 - np.log1p(a).sum() / lb) if lb > 0 else 0.0


def _per_speed(cmp: pd.DataFrame, index=None) -> pd.Series:
    s = cmp.groupby("speed")["excess"].sum()
    return s if index is None else s.reindex(index).fillna(0.0)


def bootstrap_shrink(cmp_before: pd.DataFrame, cmp_after: pd.DataFrame, n: int,
                     seed: int) -> list[float]:
    """5-95 % band of the share removed, resampling held-out speeds with replacement."""
    rng = np.random.default_rng(seed)
    b = _per_speed(cmp_before)
    vb, va = b.to_numpy(), _per_speed(cmp_after, b.index).to_numpy()
    vals = []
    for _ in range(n):
        pick = rng.choice(len(vb), len(vb), replace=True)
        before = vb[pick].sum()
        vals.append(float(1.0 - va[pick].sum() / before) if before > 0 else 0.0)
    return [float(np.percentile(vals, 5)), float(np.percentile(vals, 95))]


def setting_support(cmp_chosen: pd.DataFrame, cmp_other: pd.DataFrame | None, n: int,
                    seed: int) -> float:
    """Share of bootstrap resamples of the held-out speeds in which ``cmp_chosen`` leaves
    less held-out excess than ``cmp_other`` (ties count half; a diverged other, None, is
    beaten every time). The tables are paired speed by speed, so what they share (the
    noise, the model-form error both carry) cancels: 0.5 is "the held-out speeds do not
    tell them apart".

    Examples
    --------
    >>> import pandas as pd
    >>> a = pd.DataFrame({"speed": [1.0, 2.0, 3.0], "excess": [0.0, 1.0, 0.0]})
    >>> setting_support(a, a, 100, 0)
    0.5
    >>> setting_support(a, a.assign(excess=a.excess + 1.0), 100, 0)
    1.0
    """
    if cmp_other is None:
        return 1.0
    a = _per_speed(cmp_chosen)
    diff = (_per_speed(cmp_other, a.index) - a).to_numpy()
    if diff.size == 0:
        return 0.5
    rng = np.random.default_rng(seed)
    sums = diff[rng.integers(0, diff.size, size=(n, diff.size))].sum(axis=1)
    return float(np.mean(sums > 0) + 0.5 * np.mean(sums == 0))


def table_evidence(cmp_before: pd.DataFrame, cmp_after: pd.DataFrame, k: int = 3) -> list:
    """The features whose gap a fit removed most (its signature evidence), as text."""
    key = ["channel", "feature", "window"]
    b = cmp_before.groupby(key)["excess"].sum()
    a = cmp_after.groupby(key)["excess"].sum().reindex(b.index).fillna(0.0)
    gain = (b - a).sort_values(ascending=False)
    total = b.sum()
    out = []
    for (ch, feat, win), g in gain.head(k).items():
        if g <= 0:
            break
        out.append(f"{feat} at {ch} ({win}): {100 * g / total:.0f} % of the gap removed")
    return out


def regions_after(where: list, cmp_after: pd.DataFrame, cmp_before: pd.DataFrame) -> list:
    """Each gap region (:func:`sknarx.gap.regions`) with its held-out excess before and
    after the verdict's fit."""
    def select(c, r):
        lo, hi = r["speed_range"]
        return c[(c.channel == r["channel"]) & (c.feature == r["order"])
                 & (c.window == r["window"]) & (c.speed >= lo) & (c.speed <= hi)]

    return [{**r, "heldout_excess_before": float(select(cmp_before, r)["excess"].sum()),
             "heldout_excess_after": float(select(cmp_after, r)["excess"].sum())}
            for r in where]
