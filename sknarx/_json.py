"""JSON-safe values, for every JSON document the package writes (models, reports)."""

from __future__ import annotations

import numpy as np

__all__ = ["json_safe"]


def json_safe(x):
    """Plain JSON types; private keys (``_``) go.

    NaN (no value) becomes ``null``; an infinity (a diverged fit's error) the string
    ``"inf"`` or ``"-inf"``, which JSON cannot hold as a number.

    Examples
    --------
    >>> json_safe({"speed": float("nan"), "error": float("inf"), "_cache": 1})
    {'speed': None, 'error': 'inf'}
    """
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items() if not str(k).startswith("_")}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (np.floating, float)):
        if np.isnan(x):
            return None
        return float(x) if np.isfinite(x) else str(float(x))
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
