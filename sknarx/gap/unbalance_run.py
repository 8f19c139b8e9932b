"""``sknarx unbalance``: identify, cross-validate against two peers and predict the
unlabelled conditions (:func:`identify_unbalance`, which writes nothing); the caller
writes ``predictions.csv``, ``unbalance.json`` and ``report.html``
(:func:`write_unbalance_outputs`)."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from .._report import figure, page, provenance, quantity, table
from ..io import json_safe, write_atomic, write_text_atomic
from ..plotting import plt, save
from .unbalance import (
    RigInfluenceModel,
    UnbalanceModel,
    check_trial_runs,
    cross_validate_conditions,
    influence_from_trial_runs,
    load_campaign,
    scores,
)

__all__ = ["UnbalanceStudy", "CampaignScoring", "identify_unbalance",
           "write_unbalance_outputs", "PENALTIES"]

logger = logging.getLogger(__name__)

#: The penalties (chi-square cost of declaring a disk loaded) searched by
#: leave-one-condition-out on the labelled conditions only.
PENALTIES = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0)


@dataclass(frozen=True)
class CampaignScoring:
    """How a campaign is scored and which records the influence-coefficient peer uses:
    the campaign's own definitions, given by the rotor file's ``[unbalance]`` section
    (``examples/rk4/rotor.toml``), not by the library.

    ``loaded_gmm``: a disk counts as loaded from this unbalance (g mm);
    ``phase_from_gmm``: the phase error is scored where the applied unbalance reaches
    this (g mm); ``trial_runs``: one labelled condition per disk with a trial mass on that
    disk alone; ``thresholds_gmm``: the detection thresholds searched on the labelled
    conditions (default: six from 7/12 of ``loaded_gmm`` up to it).

    Examples
    --------
    >>> from sknarx.gap.unbalance_run import CampaignScoring
    >>> spec = {"loaded_gmm": 6.0, "phase_from_gmm": 24.0, "trial_runs": ["A007", "A015"]}
    >>> CampaignScoring.from_config({"unbalance": spec}).thresholds_gmm
    (3.5, 4.0, 4.5, 5.0, 5.5, 6.0)
    >>> CampaignScoring.from_config({"unbalance": {"loaded_gmm": 6.0}})
    Traceback (most recent call last):
    ...
    ValueError: The rotor file's [unbalance] section lacks phase_from_gmm, trial_runs (e.g. ...
    """

    loaded_gmm: float
    phase_from_gmm: float
    trial_runs: tuple[str, str]
    thresholds_gmm: tuple[float, ...]

    @classmethod
    def from_config(cls, cfg: dict) -> CampaignScoring:
        spec = cfg.get("unbalance")
        example = ("e.g. [unbalance] loaded_gmm = 6.0, phase_from_gmm = 24.0, trial_runs = "
                   "[\"A007\", \"A015\"] as in examples/rk4/rotor.toml")
        if not isinstance(spec, dict):
            raise ValueError("The rotor file needs an [unbalance] section: the campaign's "
                             f"scoring and its trial runs ({example}).")
        missing = [k for k in ("loaded_gmm", "phase_from_gmm", "trial_runs") if k not in spec]
        if missing:
            raise ValueError(f"The rotor file's [unbalance] section lacks {', '.join(missing)} "
                             f"({example}).")
        try:
            loaded, phase_from = float(spec["loaded_gmm"]), float(spec["phase_from_gmm"])
            thresholds = [float(t) for t in spec.get("thresholds_gmm", ())]
        except (TypeError, ValueError):
            raise ValueError("The rotor file's [unbalance] loaded_gmm, phase_from_gmm and "
                             "thresholds_gmm must be numbers (g mm).") from None
        runs = spec["trial_runs"]
        if isinstance(runs, str) or len(runs) != 2:
            raise ValueError("The rotor file's [unbalance] trial_runs names two conditions, "
                             f"one trial-mass run per disk, got {runs!r}.")
        if not loaded > 0 or not phase_from >= 0 or any(t <= 0 for t in thresholds):
            raise ValueError("The rotor file's [unbalance] loaded_gmm and thresholds_gmm must "
                             "be positive and phase_from_gmm not negative (g mm).")
        # the campaign's own definition is always among the thresholds searched: the
        # penalty is chosen at it
        thresholds = thresholds or [loaded * k / 12 for k in range(7, 12)]
        return cls(loaded, phase_from, (str(runs[0]), str(runs[1])),
                   tuple(sorted({*thresholds, loaded})))


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


def write_unbalance_outputs(study: UnbalanceStudy, out, command: str) -> dict:
    """Write ``predictions.csv``, ``unbalance.json`` (the study's document with its
    provenance) and ``report.html`` with its figure into ``out``; returns the document."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_atomic(out / "predictions.csv",
                 lambda tmp: study.predictions.to_csv(tmp, index=False))
    doc = json_safe({**study.document, "provenance": provenance(command)})
    write_text_atomic(out / "unbalance.json", json.dumps(doc, indent=1))
    figs = _figures(out, study.model, study.blind, study.U)
    write_text_atomic(out / "report.html", _html(doc, figs, study.rig, study.campaign))
    return doc


def _figures(out, model, blind, U):
    """Polar plots: measured and predicted response vectors of each unlabelled condition."""
    H = model.H_
    chans = model.channels_
    n = len(blind.conditions)
    if n == 0:  # a campaign of labelled conditions only: cross-validated, nothing to draw
        return {}
    cols = 5
    fig, axes = plt.subplots(int(np.ceil(n / cols)), cols, figsize=(3 * cols,
                                                                     3 * np.ceil(n / cols)),
                             squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, i in zip(axes.ravel(), range(n), strict=False):
        z = blind.z[i]
        zp = H @ U[i]
        for j in range(len(chans)):
            if np.isnan(z[j]):
                continue
            col = colors[j % len(colors)]
            ax.plot([0, z[j].real], [0, z[j].imag], "-", color=col, lw=1.5)
            ax.plot(zp[j].real, zp[j].imag, "x", color=col, ms=6)
        ax.set_title(blind.conditions[i], fontsize=9)
        ax.set_aspect("equal")
        ax.axhline(0, color="0.7", lw=0.5)
        ax.axvline(0, color="0.7", lw=0.5)
        ax.tick_params(labelsize=6)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    handles = [plt.Line2D([], [], color=colors[j % len(colors)], label=f"{s} {p}")
               for j, (s, p) in enumerate(chans)]
    fig.legend(handles=handles, loc="lower center", ncol=len(chans), fontsize=7)
    fig.suptitle("Unlabelled conditions: measured response change (lines, mils) and the "
                 "identified unbalance's prediction (x)", fontsize=9)
    fig.subplots_adjust(bottom=0.18, hspace=0.35)
    return {"polar": save(fig, out / "polar_unlabelled.png")}


_PARAM_UNITS = {"k": "N/m", "c": "N s/m", "angle": "deg", "sensitivity": "-",
                "offset": "deg"}


def _param_rows(rig, params):
    rows = []
    for name, value in zip(rig.names, params, strict=True):
        if name.endswith(("_kx", "_ky")):
            rows.append([name, quantity(10**value, "N/m")])
        elif name.endswith("_c"):
            rows.append([name, quantity(10**value, "N s/m")])
        elif name.endswith(("angle", "offset")):
            rows.append([name, quantity((np.degrees(value) + 180) % 360 - 180, "deg")])
        else:
            rows.append([name, quantity(value, "-")])
    return rows


def _html(doc, figs, rig, campaign):
    cvm = doc["cross_validation"]["methods"]
    cv_rows = [[name, quantity(v["mae_gmm"], "g mm"), f"{100 * v['detection']:.0f} %",
                quantity(v["phase_error_deg"], "deg"), f"{100 * v['localisation']:.0f} %"]
               for name, v in cvm.items()]
    pred_rows = [[p["condition_id"], p["disk"], quantity(p["U_gmm"], "g mm"),
                  quantity(p["angle_deg"], "deg"), "yes" if p["loaded"] else "no",
                  quantity(p["U_std_gmm"], "g mm"), quantity(p["angle_std_deg"], "deg")]
                 for p in doc["predictions"]]
    rm = doc["rotor_model"]
    chosen = doc["chosen_on_labelled_data"]
    params = np.array(list(rm["parameters"].values()), dtype=float)
    at_bound = []
    lo, hi = rig.bounds()
    for name, v, a, b in zip(rig.names, params, lo, hi, strict=True):
        if min(v - a, b - v) <= 1e-3 * (b - a):
            at_bound.append(name)
    bound_note = (f"Parameters on their search bound: {', '.join(at_bound)} (the data push "
                  "beyond what the rotor file allows)." if at_bound else
                  "No parameter is on its search bound.")
    corr = np.asarray(rm["correction_abs"], dtype=float)
    body = f"""<h2>Predictions for the unlabelled conditions</h2>
<p>Angles in the dataset's convention, atan2(U_im, U_re); a disk is called loaded when the
estimate reaches {quantity(chosen['loaded_threshold_gmm'], 'g mm')} (chosen on the labelled
conditions). Standard errors include the mount-to-mount scatter of
{quantity(doc['noise']['mount_scatter_gmm'], 'g mm')}.</p>
{table(pred_rows, ['condition', 'disk', '|U|', 'angle', 'loaded', 'std |U|', 'std angle'])
 if pred_rows else '<p>The feature table holds no unlabelled condition: nothing to predict.</p>'}
{''.join(figure(p) for p in figs.values())}
<h2>Leave-one-condition-out cross-validation ({doc['cross_validation']['n_conditions']}
labelled conditions)</h2>
<p>Each condition's repeats and both speeds leave together; every method is refitted
without it. Metrics as in the source: mean absolute error of |U|, detection accuracy at
{quantity(doc['cross_validation']['loaded_gmm'], 'g mm')}, phase error where |U| is at least
{quantity(doc['cross_validation']['phase_from_gmm'], 'g mm')}, localisation (the
set of loaded disks right). The influence coefficients come from the trial runs
{', '.join(doc['cross_validation']['trial_runs'])}; when one of them is held out it still
serves as its own trial run, as in the source's procedure.</p>
{table(cv_rows, ['method', 'MAE', 'detection', 'phase error', 'localisation'])}
<p class="note">Chosen on labelled data only: penalty {chosen['penalty']:g} (chi-square
cost of declaring a disk loaded) and the detection threshold; the full grid is in
unbalance.json.</p>
<h2>The rotor model, calibrated</h2>
<p>Relative residual on the labelled responses: rotor model
{100 * rm['relative_residual']['rotor model']:.0f} %, with its regularised correction
{100 * rm['relative_residual']['rotor model + correction']:.0f} % (prior width
{100 * rm['prior_width']:.0f} %; the largest correction of an influence coefficient is
{100 * corr.max():.0f} %, the median {100 * np.median(corr):.0f} %). {bound_note}</p>
{table(_param_rows(rig, params), ['parameter', 'calibrated'])}
<p class="note">Speeds: {', '.join(f'{k} {quantity(v, "rpm")}' for k, v in
                                   doc['speeds_rpm'].items())}. Response vectors in the
file's units (mils, 0-to-peak) and phase convention (lags).</p>"""
    return page("Unbalance identification through a calibrated rotor model", body,
                doc["provenance"])

