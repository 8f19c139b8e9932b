"""What the updated nominal model may get wrong: each feature's model-form tolerance.

The nominal update (:mod:`sknarx.gap.updating`) fits an axisymmetric rotor's linear
parameters to the training speeds' steady 1x. What it cannot follow there is model-form
error, and it is allowed for, feature by feature, before any effect is blamed: for the
1x, what both channels of a probe pair keep of the misfit; for every harmonic and
line, the updated model's own size (its contact law is no rig's) widened by the
harmonic's spread over what the update left uncertain; for a probe pair's orbit, its
ellipse only to the model's own (an ellipse is an effect's to explain).
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pandas as pd

from .._progress import progress_bar
from ..rotor import SimulationDivergenceError
from .gapmap import HARMONIC_TOL, circular_components, whirl_pairs

__all__ = ["prediction_spread", "common_1x_tolerance", "with_model_tolerance",
           "backward_whirl", "whirl_summary", "update_summary"]

logger = logging.getLogger(__name__)


def prediction_spread(model, speeds, update, nominal, nuis):
    """Each feature's spread (m) over what the update left uncertain, aligned with
    ``nominal`` (the updated rotor's features), and the number of principal directions.

    The spread is the root of a second moment about the updated rotor's features: half
    the squared vector difference at each of its sigma points
    (:meth:`~sknarx.gap.updating.UpdateResult.sigma_points`, an unscented transform on
    the posterior's axes), plus the whole squared difference to the rotor before the
    update. The update is fitted to the steady 1x; the bearings' contact stiffness and
    clearance barely touch the 1x but decide the journals' harmonics, by their own size
    where the orbit is about to unload the contact every revolution, and what the update
    did to a prediction no data it saw checked is no less uncertain than the change it
    made. A model that cannot predict a feature cannot blame an effect for it."""
    # same model, speeds and nuisances: the features come in ``nominal``'s order
    z0 = nominal["re"].to_numpy() + 1j * nominal["im"].to_numpy()
    var = np.zeros(z0.size)
    points = update.sigma_points()
    failed = 0
    runs = [(p, 0.5) for pair in points for p in pair] + [(update.nominal, 1.0)]
    for params, weight in progress_bar(runs, desc="update uncertainty", unit="sweep"):
        try:
            _, z, _, _ = dataclasses.replace(model, base=params).feature_arrays(speeds, nuis)
        except SimulationDivergenceError:
            failed += 1
            continue
        var += weight * np.nan_to_num(np.abs(np.asarray(z) - z0) ** 2)
    if failed:
        logger.warning("%d of the update's %d sigma points diverged: the model's "
                       "prediction spread leaves them out", failed, 2 * len(points))
    return np.sqrt(var), len(points)


def common_1x_tolerance(update) -> dict:
    """Each channel's 1x model-form tolerance (relative): the smaller of its own misfit
    after the update and its probe partner's (``yA`` for ``xA``).

    The update's parameters are those of an axisymmetric rotor on like supports: what
    they cannot follow shows in both directions of a probe pair, and that common part is
    model-form error. What one direction has beyond the other -- a split the isotropic
    parameters cannot make -- is an anisotropy's signature and is left for an effect to
    explain; taken as tolerance it hides soft pedestals (measured in docs/gap.md). A
    channel without a partner keeps its own."""
    if update is None:
        return {}
    own = update.mismatch.get("model_tolerance", {})
    swap = {"x": "y", "y": "x"}
    return {c: min(t, own.get(swap.get(c[0], c[0]) + c[1:], t)) for c, t in own.items()}


def with_model_tolerance(meas, nominal, update, rtol, spread=None):
    """The measured features with their model-form tolerance (m), fixed once from the
    updated nominal model's own features ``S``: for the 1x, what the update could not
    remove of the misfit over the training speeds that both channels of a probe pair
    share (``tau_c |S|`` beyond the comparison's ``rtol``, :func:`common_1x_tolerance`;
    a constant per-probe vector excluded); for every harmonic and
    line, ``HARMONIC_TOL |S|`` -- the model's own harmonics come from a contact law no
    rig matches -- and, in quadrature, ``spread``: the feature's spread over the
    update's uncertainty (:func:`prediction_spread`, aligned with ``nominal``). What
    exceeds that is what effects must explain. A ``whirl_tol`` column adds each probe
    pair's backward-whirl tolerance (:func:`backward_whirl`): the 1x tolerance above
    then admits a larger or smaller circle, not an ellipse. ``nominal``: the updated
    nominal model's features at every speed."""
    key = ["speed", "window", "channel", "feature"]
    nominal = nominal.copy()
    nominal["spread"] = 0.0 if spread is None else spread
    S = nominal.set_index(key).reindex(pd.MultiIndex.from_frame(meas[key]))
    size = np.hypot(S["re"].to_numpy(dtype=float), S["im"].to_numpy(dtype=float))
    tol = common_1x_tolerance(update)
    extra = {c: float(np.sqrt(max(t * t - rtol * rtol, 0.0))) for c, t in tol.items()}
    is1 = (meas["feature"] == "1x").to_numpy()
    share = np.where(is1, meas["channel"].map(extra).fillna(0.0), HARMONIC_TOL)
    widen = np.where(is1, 0.0, np.nan_to_num(S["spread"].to_numpy(dtype=float)))
    out = meas.copy()
    out["model_tol"] = np.nan_to_num(np.hypot(share * size, widen))
    out["whirl_tol"] = backward_whirl(S)
    return out


def backward_whirl(S):
    """Each probe pair's backward-whirl tolerance (m) on both of its 1x rows: the
    smaller circular component of the updated nominal model's own 1x orbit, ``|x - j y|
    / sqrt 2`` or ``|x + j y| / sqrt 2`` (0 elsewhere). The model's ellipse comes from its
    gravity-loaded contacts, whose anisotropy no rig matches, and is trusted to its
    own size as its harmonics are (``HARMONIC_TOL``); what a support stiffer in one
    direction adds beyond it is an effect's to explain (see :func:`sknarx.gap.compare`). ``S``:
    the nominal model's features aligned with the measured rows."""
    ix, iy = whirl_pairs(S.index)
    z = S["re"].to_numpy(dtype=float) + 1j * S["im"].to_numpy(dtype=float)
    p, q = circular_components(z[ix], z[iy])
    b = np.minimum(np.abs(p), np.abs(q))
    out = np.zeros(len(S))
    out[ix] = out[iy] = HARMONIC_TOL * np.nan_to_num(b)
    return out


def whirl_summary(meas) -> dict:
    """Each probe pair's backward-whirl tolerance (the ``whirl_tol`` column of
    :func:`with_model_tolerance`) over the speeds, median and largest (m), and the rule."""
    key = ["speed", "window", "channel", "feature"]
    ix, iy = whirl_pairs(pd.MultiIndex.from_frame(meas[key]))
    rows = meas.iloc[ix]
    label = rows["channel"].to_numpy() + "/" + meas["channel"].to_numpy()[iy]
    pairs = {k: {"median_m": float(g.median()), "max_m": float(g.max())}
             for k, g in rows["whirl_tol"].groupby(label)}
    return {"pairs": pairs,
            "rule": "each probe pair's 1x is compared in its forward and backward whirl: "
                    "the 1x model-form tolerance admits a larger or smaller circle "
                    "(forward whirl) only; the orbit's ellipse (backward whirl) is "
                    "trusted to the updated nominal model's own"}


def update_summary(update) -> dict | None:
    """The nominal update as plain JSON: what changed, how sure, what is inseparable."""
    if update is None:
        return None
    return {
        "updates": update.describe(),
        "parameters": update.table.to_dict(orient="records"),
        "inseparable_pairs": [{"a": a, "b": b, "correlation": c}
                              for a, b, c in update.correlated_pairs],
        "mismatch_1x": {k: v for k, v in update.mismatch.items() if k != "model_tolerance"},
        "model_tolerance_1x": common_1x_tolerance(update),
        "channel_misfit_1x": update.mismatch.get("model_tolerance", {}),
        "chi2": update.cost,
        "method": "regularised toward nominal (log-scale priors), nonlinear steady 1x at "
                  "the training speeds, sensitivities from the linearised rotor",
    }
