"""Sharing fitted models without pickle: exact JSON round trip."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

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

FORMAT = "sknarx.SpeedScheduledNarx"
FORMAT_VERSION = 1


def _floats(a):
    # json writes floats with repr(), which round-trips IEEE doubles exactly.
    return np.asarray(a, dtype=float).tolist()


def model_to_json(model, path=None) -> str:
    """JSON text of a fitted :class:`~sknarx.SpeedScheduledNarx`; also written to ``path``."""
    from . import __version__

    model_attrs = ("coef_poly_", "selected_terms_")
    for attr in model_attrs:
        if not hasattr(model, attr):
            raise ValueError("Only a fitted SpeedScheduledNarx can be exported.")
    speeds = model.speeds_
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "sknarx_version": __version__,
        "params": model.get_params(deep=False),
        "selected_terms": list(model.selected_terms_),
        "aerr_percent": _floats(model.aerr_),
        "esr_percent": float(model.esr_),
        "condition_number": float(model.condition_number_),
        "speeds_rad_s": None if speeds is None else _floats(speeds),
        "coef_per_speed": _floats(model.coef_per_speed_.to_numpy()),
        "err_per_speed": _floats(model.err_.to_numpy()),
        "speed_range_rad_s": None if model.speed_range_ is None else list(model.speed_range_),
        "speed_polynomial_scaled": _floats(model.coef_poly_),
        "speed_polynomial_raw": _floats(model.speed_polynomials_.to_numpy()),
        "output_scale": float(model.output_scale_),
    }
    text = json.dumps(doc, indent=1)
    if path is not None:
        Path(path).write_text(text)
    return text


def model_from_json(source):
    """Rebuild a fitted model from JSON text or a path to a JSON file."""
    from .narx.scheduling import SpeedScheduledNarx
    from .narx.terms import parse_terms

    text = str(source)
    if not text.lstrip().startswith("{"):
        text = Path(source).read_text()
    doc = json.loads(text)
    if doc.get("format") != FORMAT:
        raise ValueError(f"Not a sknarx model file (format {doc.get('format')!r}).")
    if doc.get("format_version", 0) > FORMAT_VERSION:
        raise ValueError(
            f"Model file format {doc['format_version']} is newer than this sknarx supports "
            f"({FORMAT_VERSION}); upgrade sknarx."
        )
    model = SpeedScheduledNarx(**doc["params"])
    names = doc["selected_terms"]
    speeds = None if doc["speeds_rad_s"] is None else np.asarray(doc["speeds_rad_s"])
    index = None if speeds is None else pd.Index(speeds, name="speed")
    model.selected_terms_ = names
    model.aerr_ = np.asarray(doc["aerr_percent"])
    model.esr_ = doc["esr_percent"]
    model.condition_number_ = doc["condition_number"]
    model.speeds_ = speeds
    model.coef_per_speed_ = pd.DataFrame(doc["coef_per_speed"], columns=names, index=index)
    model.err_ = pd.DataFrame(doc["err_per_speed"], columns=names, index=index)
    rng = doc["speed_range_rad_s"]
    model.speed_range_ = None if rng is None else tuple(rng)
    model.coef_poly_ = np.asarray(doc["speed_polynomial_scaled"])
    raw = np.asarray(doc["speed_polynomial_raw"])
    model.speed_polynomials_ = pd.DataFrame(
        raw, index=names, columns=[f"beta{j}" for j in range(raw.shape[1])]
    )
    model.output_scale_ = doc["output_scale"]
    model.coef_spline_ = None
    if model.speed_basis == "spline" and speeds is not None:
        from .narx.scheduling import _spline

        # the spline is a deterministic function of the per-speed coefficients
        model.coef_spline_ = _spline(speeds, model.coef_per_speed_.to_numpy())
    try:
        model.exponents_, model.ny_, model.nu_ = parse_terms(names)
    except ValueError:
        model.exponents_, model.ny_, model.nu_ = None, None, None
    return model
