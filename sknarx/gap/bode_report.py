"""Figures and report.html of an order-domain (Bode) diagnosis."""

from __future__ import annotations

import html
import json

import numpy as np

from ..plotting import plt, save, to_data_uri

__all__ = ["figures", "html_report"]


def figures(out, bins, s_nom, s_cal, s_best, doc, s_quasi=None):
    rpm = bins.rpm.to_numpy()
    z = bins.z.to_numpy()
    lab = doc["verdict"] if isinstance(doc["verdict"], str) else " + ".join(doc["verdict"])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a1.semilogy(rpm, np.abs(z) * 1e6, "k.", ms=3, label="measured (binned)")
    for s, style, name in ((s_nom, "c:", "nominal as described"),
                           (s_cal, "b--", "nominal, calibrated bearings"),
                           (s_best, "r-", f"corrected: {lab}")):
        a1.semilogy(rpm, np.abs(s) * 1e6, style, lw=1, label=name)
        a2.plot(rpm, np.degrees(np.angle(s)), style, lw=1)
    a2.plot(rpm, np.degrees(np.angle(z)), "k.", ms=3)
    a1.set(ylabel="1x amplitude (um, 0-pk)", title="RK-4 run-up: Bode plot")
    a1.legend(fontsize=7)
    a2.set(xlabel="speed (rpm)", ylabel="phase (deg)")
    figs = {"bode": save(fig, out / "bode.png")}
    fig, ax = plt.subplots(figsize=(5, 5))
    sel = rpm < 2400
    ax.plot(z.real[sel] * 1e6, z.imag[sel] * 1e6, "k.", ms=3, label="measured")
    for s, style, name in ((s_cal, "b--", "nominal, calibrated"), (s_best, "r-", "corrected")):
        ax.plot(s.real[sel] * 1e6, s.imag[sel] * 1e6, style, lw=1, label=name)
    ax.set(xlabel="Re 1x (um)", ylabel="Im 1x (um)", title="Polar plot (< 2400 rpm)")
    ax.set_aspect("equal")
    ax.legend(fontsize=7)
    figs["polar"] = save(fig, out / "polar.png")
    if s_quasi is not None:
        sel = (rpm > 1400) & (rpm < 2100)
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
        a1.plot(rpm[sel], np.abs(z[sel]) * 1e6, "k.-", ms=4, lw=0.5, label="measured")
        for s, style, name in ((s_quasi, "b--", f"{lab}, quasi-steady model"),
                               (s_best, "r-", f"{lab}, run-up simulated and order-tracked")):
            a1.plot(rpm[sel], np.abs(s[sel]) * 1e6, style, lw=1, label=name)
            a2.plot(rpm[sel], np.degrees(np.angle(s[sel])), style, lw=1)
        a2.plot(rpm[sel], np.degrees(np.angle(z[sel])), "k.-", ms=4, lw=0.5)
        for b in doc["response_model"].get("beat_minima_expected_rpm", []):
            a1.axvline(b, color="0.6", lw=0.6, ls=":")
        a1.set(ylabel="1x amplitude (um, 0-pk)",
               title="Through the critical: the sweep's beat (dotted: expected minima)")
        a1.legend(fontsize=7)
        a2.set(xlabel="speed (rpm)", ylabel="phase (deg)")
        figs["runup"] = save(fig, out / "runup_zoom.png")
    return figs


def html_report(doc, figs):
    v = doc["verdict"] if isinstance(doc["verdict"], str) else " + ".join(doc["verdict"])
    rows = "".join(
        f"<tr><td>{html.escape(str(r['effect']))}</td><td>{r['shrink']:.2f}</td>"
        f"<td>{html.escape(json.dumps(r['params'], default=float))}</td>"
        f"<td>{html.escape('; '.join(r['evidence']))}</td></tr>"
        for r in doc["ranking"] if r.get("testable", True))
    untested = "".join(f"<li>{html.escape(r['effect'])}: {html.escape(r['reason'])}</li>"
                       for r in doc["ranking"] if not r.get("testable", True))
    where = "".join(
        f"<tr><td>{r['rpm_range'][0]:.0f}-{r['rpm_range'][1]:.0f}</td><td>{r['order']}</td>"
        f"<td>{100 * r['share']:.1f} %</td><td>{'yes' if r['noisy_region'] else ''}</td></tr>"
        for r in doc["where"][:12])
    imgs = "".join(f'<figure><img src="{to_data_uri(p)}"></figure>' for p in figs.values())
    nc = doc["nominal_calibration"]
    rm = doc.get("response_model", {})
    vm = rm.get("verdict_heldout_excess")
    verdict_models = ("" if not vm else "Held-out excess of the verdict: " + ", ".join(
        f"{k} {v:.0f}" for k, v in vm.items()) + ".")
    located = "".join(
        f"<li>{html.escape(name)}: {loc['rpm_range'][0]:.0f}-{loc['rpm_range'][1]:.0f} rpm "
        f"({100 * loc['share_of_gain']:.0f} % of its gain)</li>"
        for name, loc in doc.get("located", {}).items() if loc.get("rpm_range"))
    bands = "".join(
        f"<tr><td>{html.escape(k)}</td><td>{v['heldout_excess_before']:.0f}</td>"
        f"<td>{v['heldout_excess_after']:.0f}</td><td>{100 * v['shrink']:.0f} %</td></tr>"
        for k, v in doc.get("gap_by_band", {}).items())
    css = ("body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto}"
           "table{border-collapse:collapse;font-size:0.85em}td,th{border:1px solid #ccc;"
           "padding:3px 6px}img{max-width:100%}")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>sknarx gap: order
domain</title><style>{css}</style></head><body><h1>Sim-to-real gap: order-domain diagnosis</h1>
<p>sknarx {html.escape(doc['sknarx_version'])}; <code>{html.escape(doc['command'])}</code></p>
<h2>Verdict: {html.escape(v)} - {100 * doc['shrink']:.0f} % of the held-out gap removed
(5-95 %: {100 * doc['shrink_band'][0]:.0f}-{100 * doc['shrink_band'][1]:.0f} %)</h2>
<h2>Nominal calibration</h2><p>The described rotor's first critical speed is
{nc['first_critical_rpm']['nominal']:.0f} rpm against the measured
{nc['first_critical_rpm']['measured']} rpm: the bearing stiffness (uncertain) was calibrated
from {nc['bearing_stiffness_N_per_m']['nominal']:.3g} to
{nc['bearing_stiffness_N_per_m']['calibrated']:.3g} +- {nc['bearing_stiffness_N_per_m']['std']:.2g}
N/m and the damping from {nc['bearing_damping_N_s_per_m']['nominal']:.3g} to
{nc['bearing_damping_N_s_per_m']['calibrated']:.3g} +- {nc['bearing_damping_N_s_per_m']['std']:.2g}
N s/m (first critical now {nc['first_critical_rpm']['calibrated']:.0f} rpm).</p>
{imgs}
<h2>Response model</h2><p>{html.escape(rm.get('kind', ''))}: {html.escape(rm.get('why', ''))}.
{html.escape(verdict_models)}</p>
<h2>Where each effect acts</h2><ul>{located}</ul>
<h2>Gap by band (held-out)</h2><table><tr><th>band</th><th>before</th><th>after</th>
<th>shrink</th></tr>{bands}</table>
<h2>Where</h2><table><tr><th>rpm</th><th>order</th><th>share of gap</th><th>noisy region</th>
</tr>{where}</table>
<h2>Which</h2><table><tr><th>candidate</th><th>shrink</th><th>parameters</th><th>evidence</th>
</tr>{rows}</table><p>Not testable with these data:</p><ul>{untested}</ul>
<h2>Limits</h2><ul>{''.join(f'<li>{html.escape(x)}</li>' for x in doc['limits'])}</ul>
</body></html>"""
