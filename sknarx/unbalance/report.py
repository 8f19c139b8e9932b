"""``predictions.csv``, ``unbalance.json`` and ``report.html`` of an unbalance study."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._report import figure, page, provenance, quantity, table
from ..io import json_safe, write_atomic, write_text_atomic
from ..plotting import legend_below, plt, save
from .study import UnbalanceStudy

__all__ = ["write_unbalance_outputs"]


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
    rect = legend_below(fig, handles=handles, ncol=len(chans))
    fig.suptitle("Unlabelled conditions: measured response change (lines, mils) and the "
                 "identified unbalance's prediction (x)", fontsize=9)
    return {"polar": save(fig, out / "polar_unlabelled.png", rect=rect)}


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
