"""``sknarx unbalance``'s computation: identify, cross-validate against two peers and
predict the unlabelled conditions (:func:`identify_unbalance`, which writes nothing)."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pandas as pd

from .campaign import CampaignScoring, check_trial_runs, influence_from_trial_runs, load_campaign
from .model import RigInfluenceModel, UnbalanceModel, cross_validate_conditions, scores

__all__ = ["UnbalanceStudy", "identify_unbalance", "PENALTIES"]

logger = logging.getLogger(__name__)

#: The penalties (chi-square cost of declaring a disk loaded) searched by
#: leave-one-condition-out on the labelled conditions only.
PENALTIES = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0)


def _ls_solve(H, z):
    ok = ~np.isnan(z)
    u, *_ = np.linalg.lstsq(H[ok], z[ok], rcond=None)
    return u


def _peers(campaign, trial_runs, seed=0):
    """Leave-one-condition-out predictions of the influence-coefficient method (from the
    two trial runs), a least-squares influence matrix and a random forest."""
    from sklearn.ensemble import RandomForestRegressor

    keep = campaign.labeled & (np.asarray(campaign.block) != "baseline")
    lab = campaign.subset(keep)
    H_ic = influence_from_trial_runs(campaign, *trial_runs)
    X = np.column_stack([campaign.z.real, campaign.z.imag])
    Y = np.column_stack([campaign.U.real, campaign.U.imag])
    out = {"influence coefficients (trial runs)": [], "least-squares influence matrix": [],
           "random forest": []}
    labelled = np.flatnonzero(campaign.labeled)
    for c in lab.conditions:
        i = campaign.conditions.index(c)
        z = campaign.z[i]
        out["influence coefficients (trial runs)"].append(_ls_solve(H_ic, z))
        train = [j for j in labelled if j != i]
        Z, U = campaign.z[train], campaign.U[train]
        H_ls = np.array([np.linalg.lstsq(U[~np.isnan(Z[:, k])], Z[~np.isnan(Z[:, k]), k],
                                         rcond=None)[0] for k in range(Z.shape[1])])
        out["least-squares influence matrix"].append(_ls_solve(H_ls, z))
        rf = RandomForestRegressor(n_estimators=200, random_state=seed, n_jobs=1)
        rf.fit(X[train], Y[train])
        y = rf.predict(X[i : i + 1])[0]
        out["random forest"].append(y[:2] + 1j * y[2:])
    return {k: np.array(v) for k, v in out.items()}, lab.U


@dataclass
class UnbalanceStudy:
    """What :func:`identify_unbalance` found: the JSON-able ``document`` (every key of
    ``unbalance.json`` but ``provenance``, which the writer adds), the ``predictions``
    table of the unlabelled conditions (``U_gmm`` in g mm, angles in deg), and the fitted
    ``model``, its ``rig``, the ``campaign`` and the unlabelled part (``blind``, with its
    identified unbalance ``U``, g mm) the report's figures are drawn from."""

    document: dict
    predictions: pd.DataFrame
    model: UnbalanceModel
    rig: RigInfluenceModel
    campaign: object
    blind: object
    U: np.ndarray


def identify_unbalance(features, cfg: dict) -> UnbalanceStudy:
    """Fit, cross-validate against the peers and predict the unlabelled conditions of a
    campaign's 1x features; nothing is written. ``cfg``: the rotor file, with the
    campaign's scoring and trial runs in its ``[unbalance]`` section
    (:class:`CampaignScoring`)."""
    scoring = CampaignScoring.from_config(cfg)
    campaign = load_campaign(features)
    try:  # before the long calibration: a wrong trial run is the rotor file's mistake
        check_trial_runs(campaign, scoring.trial_runs)
    except ValueError as exc:
        raise ValueError(f"The rotor file's [unbalance] trial_runs: {exc}") from exc
    probes = tuple(dict.fromkeys(p for _, p in campaign.channels))
    rig = RigInfluenceModel(cfg, campaign.speeds_rpm, probes)
    n_lab = int(campaign.labeled.sum())
    # each fold calibrates the rotor model without one labelled condition: what is left
    # must hold more numbers (two per complex channel) than the model has parameters
    per_condition = 2 * len(campaign.channels)
    if (n_lab - 1) * per_condition <= len(rig.names):
        need = len(rig.names) // per_condition + 2
        raise ValueError(f"The feature table holds {n_lab} labelled condition(s) of "
                         f"{len(campaign.channels)} channels; the rotor model's "
                         f"{len(rig.names)} parameters are calibrated without each in turn: "
                         f"give at least {need}.")
    logger.info("%d conditions (%d labelled) x %d channels; calibrating the rotor model "
                "(%d parameters, %d starts)", len(campaign.conditions), n_lab,
                len(campaign.channels), len(rig.names), rig.n_starts)
    model = UnbalanceModel(rig).fit(campaign)
    logger.info("rotor model explains the labelled responses to %.0f %% (relative "
                "residual), %.0f %% with its correction; mount scatter %.2f g mm",
                100 * model.relative_residual_["rotor model"],
                100 * model.relative_residual_["rotor model + correction"],
                np.sqrt(model.tau2_))
    loaded = scoring.loaded_gmm
    cv = cross_validate_conditions(model, campaign, PENALTIES, scoring.thresholds_gmm,
                                   loaded_gmm=loaded, phase_from_gmm=scoring.phase_from_gmm)
    # settings chosen on the labelled conditions only: the penalty for the lowest MAE,
    # then the detection threshold for the best detection at that penalty
    best_p = min(PENALTIES, key=lambda p: cv["scores"][(p, loaded)]["mae_gmm"])
    best_t = max(scoring.thresholds_gmm, key=lambda t: (
        cv["scores"][(best_p, t)]["detection"], -abs(t - loaded)))
    model.penalty = best_p
    logger.info("chosen on labelled data: penalty %.1f, decide loaded at %.1f g mm", best_p,
                best_t)
    peers, truth = _peers(campaign, scoring.trial_runs)
    table_rows = {"model-based (this package)": scores(
        cv["predictions"][best_p], truth, loaded, scoring.phase_from_gmm, decide_at=best_t)}
    for name, pred in peers.items():
        table_rows[name] = scores(pred, truth, loaded, scoring.phase_from_gmm)

    blind = campaign.subset(~campaign.labeled)
    U, var, supp = model.predict(blind)
    rows = []
    for i, c in enumerate(blind.conditions):
        for d in range(2):
            mag = float(abs(U[i, d]))
            sd = float(np.sqrt(var[i][d] / 2))  # per component of a circular complex error
            rows.append({"condition_id": c, "disk": d + 1, "U_gmm": mag,
                         "angle_deg": float(np.degrees(np.angle(U[i, d]))),
                         "loaded": bool(mag >= best_t), "U_std_gmm": sd,
                         "angle_std_deg": float(min(np.degrees(sd / mag), 180.0))
                         if mag > 0 else 180.0})
    doc = {
        "predictions": rows,
        "cross_validation": {"scheme": "leave one condition out (its repeats and both "
                             "speeds leave together)", "n_conditions": len(cv["conditions"]),
                             "trial_runs": list(scoring.trial_runs),
                             "loaded_gmm": loaded,
                             "phase_from_gmm": scoring.phase_from_gmm,
                             "methods": table_rows,
                             "grid": {f"penalty {p:g}, threshold {t:g}": v
                                      for (p, t), v in cv["scores"].items()}},
        "chosen_on_labelled_data": {"penalty": best_p, "loaded_threshold_gmm": best_t},
        "rotor_model": {"parameters": dict(zip(rig.names, model.params_.tolist(),
                                               strict=True)),
                        "relative_residual": model.relative_residual_,
                        "correction_abs": np.abs(model.delta_).tolist(),
                        "prior_width": model.prior_width},
        "noise": {"mount_scatter_gmm": float(np.sqrt(model.tau2_)),
                  "channel_noise": dict(zip([f"{s} {p}" for s, p in campaign.channels],
                                            np.sqrt(model.sigma2_).tolist(), strict=True))},
        "speeds_rpm": campaign.speeds_rpm,
    }
    # the columns stated, so a campaign with nothing to predict still writes its header
    columns = ["condition_id", "disk", "U_gmm", "angle_deg", "loaded", "U_std_gmm",
               "angle_std_deg"]
    return UnbalanceStudy(document=doc, predictions=pd.DataFrame(rows, columns=columns),
                          model=model,
                          rig=rig, campaign=campaign, blind=blind, U=U)
