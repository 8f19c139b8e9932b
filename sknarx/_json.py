"""JSON-safe values, for every JSON document the package writes (models, reports)."""

from __future__ import annotations

import numpy as np

__all__ = ["json_safe"]


def json_safe(x):
    """Plain JSON types; inf/NaN become strings a reader can see; private keys (``_``) go."""
    if isinstance(x, dict):
        return {str(k): json_safe(v) for k, v in x.items() if not str(k).startswith("_")}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return json_safe(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else str(float(x))
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
