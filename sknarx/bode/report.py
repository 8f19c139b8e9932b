"""diagnosis.json, bode_fit.csv, figures and report.html of an order-domain diagnosis."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd

from .._report import figure, page, provenance, quantity, table, value_range
from ..gap.report_text import alike_text, verdict_text
from ..io import json_safe, write_atomic, write_text_atomic
from ..plotting import legend_below, plt, save

__all__ = ["figures", "html_report", "write_bode_outputs"]


def write_bode_outputs(result, out, command: str) -> dict:
    """Write the report of an order-domain :class:`~sknarx.gap.GapDiagnosis`:
    ``diagnosis.json``, ``bode_fit.csv`` (measured and modelled 1x per revolution), the
    figures and ``report.html``; returns the JSON document."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    c = result.curves
    doc = json_safe(dict(result))
    prov = provenance(command)
    doc.update(sknarx_version=prov["sknarx_version"], command=command, provenance=prov)
    fit = _bode_fit_table(c["rows"], c["bins"], c["nominal"], c["calibrated"],
                          c["corrected"], c["measurement"])
    write_atomic(out / "bode_fit.csv", lambda tmp: fit.to_csv(tmp, index=False))
    figs = figures(out, c["bins"], c["nominal"], c["calibrated"], c["corrected"], doc,
                   c["quasi_steady"], z2=c["z2"], label=c["corrected_label"])
    write_text_atomic(out / "diagnosis.json", json.dumps(doc, indent=1))
    write_text_atomic(out / "report.html", html_report(doc, figs))
    return doc


def figures(out, bins, s_nom, s_cal, s_best, doc, s_quasi=None, z2=None, label=None):
    """Bode, polar, run-up zoom and residual figures; ``label`` names the corrected
    model (the verdict's by default)."""
    rpm = bins.rpm.to_numpy()
    z = bins.z.to_numpy()
    lab = label or (doc["verdict"] if isinstance(doc["verdict"], str)
                    else " + ".join(doc["verdict"]))
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a1.semilogy(rpm, np.abs(z) * 1e6, "k.", ms=3, label="measured (binned)")
    for s, style, name in ((s_nom, "c:", "nominal as described"),
                           (s_cal, "b--", "nominal, calibrated bearings"),
                           (s_best, "r-", f"corrected: {lab}")):
        a1.semilogy(rpm, np.abs(s) * 1e6, style, lw=1, label=name)
        a2.plot(rpm, np.degrees(np.angle(s)), style, lw=1)
    a2.plot(rpm, np.degrees(np.angle(z)), "k.", ms=3)
    a1.set(ylabel="1x amplitude (µm, 0-pk)",
           title="Bode plot: measured, nominal, corrected")
    a2.set(xlabel="speed (rpm)", ylabel="phase (deg)")
    figs = {"bode": save(fig, out / "bode.png", rect=legend_below(fig, a1, ncol=2))}
    crit = float(doc["nominal_calibration"]["first_critical_rpm"]["calibrated"])
    fig, ax = plt.subplots(figsize=(5, 5))
    sel = rpm < 1.5 * crit  # through the first critical; the plateau above crowds the origin
    ax.plot(z.real[sel] * 1e6, z.imag[sel] * 1e6, "k.", ms=3, label="measured")
    for s, style, name in ((s_cal, "b--", "nominal, calibrated"), (s_best, "r-", "corrected")):
        ax.plot(s.real[sel] * 1e6, s.imag[sel] * 1e6, style, lw=1, label=name)
    ax.set(xlabel="Re 1x (µm)", ylabel="Im 1x (µm)",
           title=f"Polar plot (below {1.5 * crit:.0f} rpm)")
    ax.set_aspect("equal")
    figs["polar"] = save(fig, out / "polar.png", rect=legend_below(fig, ax))
    if s_quasi is not None:
        sel = (rpm > 0.85 * crit) & (rpm < 1.3 * crit)
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
        a1.plot(rpm[sel], np.abs(z[sel]) * 1e6, "k.-", ms=4, lw=0.5, label="measured")
        for s, style, name in ((s_quasi, "b--", f"{lab}, quasi-steady model"),
                               (s_best, "r-", f"{lab}, run-up simulated and order-tracked")):
            a1.plot(rpm[sel], np.abs(s[sel]) * 1e6, style, lw=1, label=name)
            a2.plot(rpm[sel], np.degrees(np.angle(s[sel])), style, lw=1)
        a2.plot(rpm[sel], np.degrees(np.angle(z[sel])), "k.-", ms=4, lw=0.5)
        for b in doc["response_model"].get("beat_minima_expected_rpm", []):
            a1.axvline(b, color="0.6", lw=0.6, ls=":")
        a1.set(ylabel="1x amplitude (µm, 0-pk)",
               title="Through the critical: the sweep's beat (dotted: expected minima)")
        a2.set(xlabel="speed (rpm)", ylabel="phase (deg)")
        figs["runup"] = save(fig, out / "runup_zoom.png",
                             rect=legend_below(fig, a1, ncol=3))
    if z2:
        figs["residual"] = _residual_figure(out, rpm, z2, doc)
    return figs


def _residual_figure(out, rpm, z2, doc):
    """Normalised squared residual per bin (chi-square with 2 degrees of freedom when
    the model is right): where the corrected model still disagrees."""
    fig, ax = plt.subplots(figsize=(7, 3.2))
    for (name, v), style in zip(z2.items(), ("b.", "r."), strict=False):
        ax.semilogy(rpm, np.clip(v, 1e-2, None), style, ms=3, label=name)
    thr = doc["significant_z2"]
    ax.axhline(thr, color="0.4", lw=0.8, ls="--",
               label=f"{thr:.2f}: significant (p = {np.exp(-thr / 2):.3f} if the model is right)")
    for r in doc.get("remaining", [])[:4]:
        ax.axvspan(*r["rpm_range"], color="orange", alpha=0.15, lw=0)
    ax.set(xlabel="speed (rpm)", ylabel="|z - model|^2 / variance",
           title="What remains after the diagnosis (shaded: remaining regions)")
    return save(fig, out / "residual.png", rect=legend_below(fig, ax))


def html_report(doc, figs):
    v = doc["verdict"] if isinstance(doc["verdict"], str) else " + ".join(doc["verdict"])
    which = table(
        ([r["effect"] if isinstance(r["effect"], str) else " + ".join(r["effect"]),
          f"{100 * r['shrink']:.0f} %", _params(r["params"]),
          "; ".join(r["evidence"])] for r in doc["ranking"] if r.get("testable", True)),
        ["candidate", "held-out gap removed", "fitted parameters", "evidence"])
    untested = "".join(f"<li>{html.escape(r['effect'])}: {html.escape(r['reason'])}</li>"
                       for r in doc["ranking"] if not r.get("testable", True))
    where = table(
        ([value_range(*r["rpm_range"], "rpm", 0), r["order"], f"{100 * r['share']:.1f} %",
          "yes" if r["noisy_region"] else ""] for r in doc["where"][:12]),
        ["speeds", "order", "share of the gap", "noisy region"],
        empty="No bin differs significantly from the calibrated nominal model.")
    imgs = "".join(figure(p) for p in figs.values())
    remaining = table(
        ([value_range(*r["rpm_range"], "rpm", 0), r["order"], f"{100 * r['share']:.1f} %",
          "yes" if r["noisy_region"] else ""] for r in doc.get("remaining", [])[:12]),
        ["speeds", "order", "share of what remains", "noisy region"],
        empty="No bin differs significantly from the corrected model.")
    nc = doc["nominal_calibration"]
    k, c, fc = (nc["bearing_stiffness_N_per_m"], nc["bearing_damping_N_s_per_m"],
                nc["first_critical_rpm"])
    measured_fc = (f"against the rotor file's first_critical_rpm "
                   f"{quantity(fc['measured'], 'rpm')}"
                   if fc.get("measured") else "(no measured value in the rotor file)")
    rm = doc.get("response_model", {})
    vm = rm.get("verdict_heldout_excess")
    verdict_models = ("" if not vm else "Held-out excess of the verdict: " + ", ".join(
        f"{name} {val:.0f}" for name, val in vm.items()) + " (dimensionless).")
    located = "".join(
        f"<li>{html.escape(name)}: {value_range(*loc['rpm_range'], 'rpm', 0)} "
        f"({100 * loc['share_of_gain']:.0f} % of its gain)</li>"
        for name, loc in doc.get("located", {}).items() if loc.get("rpm_range"))
    bands = table(
        ([name, f"{val['heldout_excess_before']:.0f}", f"{val['heldout_excess_after']:.0f}",
          f"{100 * val['shrink']:.0f} %"] for name, val in doc.get("gap_by_band", {}).items()),
        ["band", "held-out excess before", "after", "removed"])
    band = doc.get("shrink_band")
    band_text = (f" (bootstrap 5-95 %: {100 * band[0]:.0f}-{100 * band[1]:.0f} %)" if band
                 else "")
    # what a named effect cannot be told from, or what the closest candidate of an
    # unexplained one missed, is stated where the verdict is
    alike = (alike_text(doc["verdict"]).strip()
             if doc["verdict"] not in ("no-gap", "unexplained") else verdict_text(doc))
    body = f"""<h2>Verdict: {html.escape(v)} - {100 * doc['shrink']:.0f} % of the held-out gap
removed{band_text}</h2>{f'<p>{html.escape(alike)}</p>' if alike else ''}
<h2>Nominal calibration</h2><p>The described rotor's first critical speed is
{quantity(fc['nominal'], 'rpm')} {html.escape(measured_fc)}: the bearing stiffness was
calibrated from {quantity(k['nominal'], 'N/m')} to {quantity(k['calibrated'], 'N/m')}
+- {quantity(k['std'], 'N/m', 2)} and the damping from {quantity(c['nominal'], 'N s/m')} to
{quantity(c['calibrated'], 'N s/m')} +- {quantity(c['std'], 'N s/m', 2)} (first critical now
{quantity(fc['calibrated'], 'rpm')}).</p>
{imgs}
<h2>Modes of the corrected rotor</h2>
{table(([f"mode {i + 1}", f"{quantity(m['rpm'], 'rpm', 4)} +- {quantity(m['rpm_std'], 'rpm', 2)}",
         f"{m['damping_ratio']:.4f} +- {m['damping_ratio_std']:.4f}",
         f"{m['sweep_parameter']:.2f}" if "sweep_parameter" in m else "-"]
        for i, m in enumerate(doc.get('modes', []))),
       ["mode", "natural frequency at rest", "damping ratio",
        "sweep parameter alpha/(zeta w_n)^2"])}
<p class="note">{_sweep_text(doc.get('sweep', {}))} {_beat_text(rm.get('beat'))}</p>
<h2>Response model</h2><p>{html.escape(rm.get('kind', ''))}: {html.escape(rm.get('why', ''))}.
{html.escape(verdict_models)}</p>
<h2>Where each effect acts</h2><ul>{located}</ul>
<h2>Gap by band (held-out)</h2>{bands}
<h2>Where</h2>{where}
<h2>What remains after the diagnosis</h2>{remaining}
<h2>Which</h2>{which}<p>Not testable with these data:</p><ul>{untested}</ul>
<h2>What these data cannot tell</h2>
<ul>{''.join(f'<li>{html.escape(x)}</li>' for x in doc['limits'])}</ul>"""
    return page("Sim-to-real gap: order-domain diagnosis", body, doc["provenance"])


def _beat_text(beat) -> str:
    if not beat:
        return ""
    rms = beat["complex_residual_rms_m"]
    parts = [f"Beat behind the peak: amplitude minima measured at "
             f"{', '.join(f'{x:.0f}' for x in beat['measured_minima_rpm'])} rpm, in the swept "
             f"model at {', '.join(f'{x:.0f}' for x in beat['swept_model_minima_rpm'])} rpm "
             f"(the linear-sweep beat law: "
             f"{', '.join(f'{x:.0f}' for x in beat['expected_minima_rpm'])} rpm). Complex "
             f"residual from {beat['above_peak_rpm'][0]:.0f} to {beat['above_peak_rpm'][1]:.0f} "
             "rpm: " + ", ".join(f"{k} {quantity(v, 'm')}" for k, v in rms.items()) + "."]
    if "quasi_over_swept" in beat:
        parts.append(f"The quasi-steady model's residual is {beat['quasi_over_swept']:.2f} "
                     "times the swept model's there.")
    return html.escape(" ".join(parts))


def _sweep_text(sweep) -> str:
    if not sweep or sweep.get("rate_rpm_s") is None:
        return "The record is not a run-up: steady-state responses apply."
    valid = "valid" if sweep["quasi_steady_valid"] else "NOT valid"
    return html.escape(
        f"Run-up rate {quantity(sweep['rate_rpm_s'], 'rpm/s')}; sweep parameter "
        f"{sweep['sweep_parameter']:.2f} ({sweep['measure']}), against a limit of "
        f"{sweep['limit']:g}: a quasi-steady (steady-state Bode) model is {valid} here.")


_UNITS = {"bearing_damping": "N s/m", "bearing_stiffness": "N/m", "kx": "N/m", "ky": "N/m",
          "cx": "N s/m", "cy": "N s/m",
          "probe_angle_deg": "deg", "runout_amplitude_m": "m", "runout_phase_deg": "deg",
          "critical_speed_rpm": "rpm", "critical_speeds_rpm": "rpm"}


def _params(params) -> str:
    parts = []
    for key, value in params.items():
        unit = _UNITS.get(key, "")
        if isinstance(value, (list, tuple)):
            parts.append(f"{key} " + ", ".join(quantity(x, unit, 4) for x in value))
        else:
            parts.append(f"{key} {quantity(value, unit, 4)}")
    return "; ".join(parts)


def _bode_fit_table(rows, bins, s_nom, s_cal, s_best, meas_cfg):
    """Measured and modelled 1x per revolution, in the input's units and phase convention
    (the models, computed per speed bin, are interpolated to each revolution's speed)."""
    scale = float(meas_cfg.get("amplitude_scale", 1.0))
    rpm = rows.rpm.to_numpy()
    b = bins.rpm.to_numpy()  # beyond the end bins' centres the end values hold
    out = {"rpm": rpm, "measured_amp": np.abs(rows.z.to_numpy()) / scale,
           "measured_phase_deg": np.degrees(np.angle(rows.z.to_numpy()))}
    for name, s in (("nominal", s_nom), ("corrected", s_best)):
        zi = np.interp(rpm, b, s.real) + 1j * np.interp(rpm, b, s.imag)
        out[f"{name}_amp"] = np.abs(zi) / scale
        out[f"{name}_phase_deg"] = np.degrees(np.angle(zi))
    return pd.DataFrame(out)[["rpm", "measured_amp", "measured_phase_deg", "nominal_amp",
                              "nominal_phase_deg", "corrected_amp", "corrected_phase_deg"]]
