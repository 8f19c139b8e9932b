"""The fitted state of a SpeedScheduledNarx as a plain JSON document, and back.

The estimator owns its format (``SpeedScheduledNarx.to_json`` / ``from_json``);
:mod:`sknarx.io` only reads and writes files. Floats are written with ``repr``,
which round-trips IEEE doubles exactly.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from .._version import __version__

FORMAT = "sknarx.SpeedScheduledNarx"
#: 2 adds the uncertainty (per-speed covariances, residual variances, degrees of
#: freedom) and the noise terms of NARMAX models; format 1 files still load.
FORMAT_VERSION = 2


def _floats(a):
    return None if a is None else np.asarray(a, dtype=float).tolist()


def model_state(model) -> dict:
    """JSON-ready document of a fitted model."""
    speeds = model.speeds_
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "sknarx_version": __version__,
        "params": model.get_params(deep=False),
        "selected_terms": list(model.selected_terms_),
        "noise_terms": list(model.noise_terms_),
        "aerr_percent": _floats(model.aerr_),
        "esr_percent": float(model.esr_),
        "condition_number": float(model.condition_number_),
        "n_iter": int(model.n_iter_),
        "speeds_rad_s": None if speeds is None else _floats(speeds),
        "coef_per_speed": _floats(model.coef_per_speed_.to_numpy()),
        "coef_std_err_per_speed": _floats(model.coef_std_err_per_speed_.to_numpy()),
        "coef_cov_per_speed": _floats(model.coef_cov_per_speed_),
        "noise_variance_per_speed": _floats(model.noise_variance_per_speed_),
        "dof_per_speed": _floats(model.dof_per_speed_),
        "err_per_speed": _floats(model.err_.to_numpy()),
        "speed_range_rad_s": None if model.speed_range_ is None else list(model.speed_range_),
        "speed_polynomial_scaled": _floats(model.coef_poly_),
        "speed_polynomial_scaled_cov": (None if getattr(model, "coef_poly_cov_", None) is None
                                        else _floats(model.coef_poly_cov_)),
        "speed_polynomial_raw": _floats(model.speed_polynomials_.to_numpy()),
        "speed_polynomial_raw_std_err": _floats(model.speed_polynomials_std_err_.to_numpy()),
        "output_scale": float(model.output_scale_),
    }


def check_document(doc: dict) -> None:
    """Reject documents that are not models of this format (or of a newer one)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ValueError(f"Not a sknarx model file (format {found!r}; expected {FORMAT!r}).")
    if doc.get("format_version", 0) > FORMAT_VERSION:
        raise ValueError(
            f"Model file format {doc['format_version']} is newer than this sknarx supports "
            f"({FORMAT_VERSION}); upgrade sknarx."
        )


def restore_state(model, doc: dict) -> None:
    """Set the fitted attributes of ``model`` (built from ``doc['params']``) from ``doc``."""
    names = doc["selected_terms"]
    speeds = None if doc["speeds_rad_s"] is None else np.asarray(doc["speeds_rad_s"])
    index = None if speeds is None else pd.Index(speeds, name="speed")
    coef = np.asarray(doc["coef_per_speed"], dtype=float)
    model.selected_terms_ = names
    model.noise_terms_ = list(doc.get("noise_terms", []))
    model.aerr_ = np.asarray(doc["aerr_percent"], dtype=float)
    model.esr_ = doc["esr_percent"]
    model.condition_number_ = doc["condition_number"]
    model.n_iter_ = int(doc.get("n_iter", 0))
    model.speeds_ = speeds
    model.coef_per_speed_ = pd.DataFrame(coef, columns=names, index=index)
    model.err_ = pd.DataFrame(np.asarray(doc["err_per_speed"], dtype=float), columns=names,
                               index=index)
    cov = doc.get("coef_cov_per_speed")  # absent in format 1: no uncertainty saved
    nan = np.full(coef.shape, np.nan)
    model.coef_cov_per_speed_ = None if cov is None else np.asarray(cov, dtype=float)
    model.coef_std_err_per_speed_ = pd.DataFrame(
        nan if cov is None else np.asarray(doc["coef_std_err_per_speed"], dtype=float),
        columns=names, index=index)
    model.noise_variance_per_speed_ = np.asarray(
        doc.get("noise_variance_per_speed") or np.full(coef.shape[0], np.nan), dtype=float)
    model.dof_per_speed_ = np.asarray(
        doc.get("dof_per_speed") or np.full(coef.shape[0], np.nan), dtype=float)
    rng = doc["speed_range_rad_s"]
    model.speed_range_ = None if rng is None else tuple(rng)
    model.coef_poly_ = np.asarray(doc["speed_polynomial_scaled"], dtype=float)
    poly_cov = doc.get("speed_polynomial_scaled_cov")  # refined speed functions only
    model.coef_poly_cov_ = None if poly_cov is None else np.asarray(poly_cov, dtype=float)
    raw = np.asarray(doc["speed_polynomial_raw"], dtype=float)
    cols = [f"beta{j}" for j in range(raw.shape[1])]
    model.speed_polynomials_ = pd.DataFrame(raw, index=names, columns=cols)
    raw_se = doc.get("speed_polynomial_raw_std_err")
    model.speed_polynomials_std_err_ = pd.DataFrame(
        np.full(raw.shape, np.nan) if raw_se is None else np.asarray(raw_se, dtype=float),
        index=names, columns=cols)
    model.output_scale_ = float(doc["output_scale"])


def read_json_document(source) -> dict:
    """A model document from JSON text or from the path of a JSON file."""
    text = str(source)
    if not text.lstrip().startswith("{"):
        text = Path(source).read_text()
    return json.loads(text)
