"""Files: fitted models as JSON (exact round trip, no pickle) and JSON-safe values."""

from __future__ import annotations

import numpy as np

__all__ = ["model_to_json", "model_from_json", "json_safe"]


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

def model_to_json(model, path=None) -> str:
    """JSON text of a fitted :class:`~sknarx.SpeedScheduledNarx`; also written to ``path``.

    The estimator owns its format (:meth:`~sknarx.SpeedScheduledNarx.to_json`).
    """
    if not hasattr(model, "to_json") or not hasattr(model, "coef_poly_"):
        raise ValueError("Only a fitted SpeedScheduledNarx can be exported.")
    return model.to_json(path)


def model_from_json(source):
    """Rebuild a fitted model from JSON text or a path to a JSON file."""
    from .narx.scheduling import SpeedScheduledNarx

    return SpeedScheduledNarx.from_json(source)
