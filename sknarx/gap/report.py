"""diagnosis.json, figures and report.html of a time-series gap diagnosis."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from .._report import figure, page, provenance, quantity, table, value_range
from ..io import json_safe, write_atomic, write_text_atomic
from ..orders import NONSYNC_LABELS
from ..plotting import plt, save
from .report_text import (
    discrete_text,
    effect_parameters,
    label,
    linear_form_text,
    verdict_text,
)
from .sweep_model import NUISANCE_UNITS

__all__ = ["write_gap_outputs", "heatmap", "candidate_label"]

FEATURE_ORDER = ["1/3x", "1/2x", "1x", "2x", "3x", *NONSYNC_LABELS]


def heatmap(cmp, path, title):
    """log10(1 + z2) over speed x feature, one panel per channel and window."""
    chans = sorted(cmp.channel.unique())
    # settled records have no transient window: one row of panels, not an empty one
    wins = [w for w in ("transient", "steady") if (cmp.window == w).any()]
    fig, axes = plt.subplots(len(wins), len(chans), figsize=(3.2 * len(chans), 5.2),
                             squeeze=False, sharex=True, sharey=True)
    vmax = np.log10(1 + cmp.z2.max())
    for i, win in enumerate(wins):
        for j, ch in enumerate(chans):
            ax = axes[i, j]
            g = cmp[(cmp.channel == ch) & (cmp.window == win)]
            piv = g.pivot_table(index="feature", columns="speed", values="z2").reindex(
                FEATURE_ORDER)
            im = ax.imshow(np.log10(1 + piv.to_numpy()), aspect="auto", origin="lower",
                           cmap="magma", vmin=0, vmax=vmax)
            ax.set_yticks(range(len(FEATURE_ORDER)), FEATURE_ORDER, fontsize=7)
            sp = piv.columns.to_numpy()
            ticks = np.linspace(0, len(sp) - 1, min(5, len(sp))).astype(int)
            ax.set_xticks(ticks, [f"{sp[k]:.0f}" for k in ticks], fontsize=7)
            ax.set_title(f"{ch}, {win}", fontsize=8)
            ax.grid(False)
            if i == len(wins) - 1:
                ax.set_xlabel("speed (rad/s)", fontsize=8)
    fig.colorbar(im, ax=axes, shrink=0.6, label="log10(1 + z^2)")
    fig.suptitle(title)
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return Path(path)


def write_gap_outputs(result, out, command: str, narx: dict | None = None) -> dict:
    """Write ``diagnosis.json``, the figures and ``report.html`` of a time-series
    :class:`~sknarx.gap.GapDiagnosis`; returns the JSON document."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tables = result.tables
    figs = {}
    if "all" in tables:
        figs["map"] = heatmap(tables["all"], out / "gap_map.png",
                              "Gap map after nuisance calibration (all speeds)")
    if "after" in tables:
        figs["after"] = heatmap(tables["after"], out / "gap_map_after.png",
                                f"Held-out gap with the verdict ({label(result['verdict'])})")
    if result["ranking"]:
        fig, ax = plt.subplots(figsize=(6, 3))
        names = [candidate_label(r) for r in result["ranking"]]
        ax.barh(names[::-1], [max(r["shrink"], 0) for r in result["ranking"]][::-1])
        ax.set(xlabel="share of the held-out gap removed", xlim=(0, 1))
        figs["ranking"] = save(fig, out / "ranking.png")
    doc = json_safe({k: v for k, v in result.items() if not k.startswith("_")})
    prov = provenance(command)
    doc["sknarx_version"] = prov["sknarx_version"]
    doc["command"] = command
    doc["provenance"] = prov
    if narx is not None:
        doc["narx"] = json_safe(narx)
    write_text_atomic(out / "diagnosis.json", json.dumps(doc, indent=1))
    write_text_atomic(out / "report.html", _html(doc, figs, prov))
    return doc


def _update_html(upd) -> str:
    """The nominal model update: what changed (model error, not an effect), how sure,
    and what these data cannot tell apart."""
    if not upd:
        return ""
    rows = [[r["label"], r["parameter"], quantity(r["nominal"]), quantity(r["updated"]),
             (f"{100 * r['change']:+.1f} % +- {100 * r['std']:.1f} %" if r["log"] else
              f"{np.degrees(r['change']):+.1f} deg +- {np.degrees(r['std']):.1f} deg"),
             f"{r['resolution']:.2f}", "yes" if r["significant"] else ""]
            for r in upd["parameters"]]
    pairs = "".join(f"<li>{html.escape(p['a'])} and {html.escape(p['b'])} (correlation "
                    f"{p['correlation']:+.2f})</li>" for p in upd["inseparable_pairs"])
    mm = upd["mismatch_1x"]
    listed = ("; ".join(upd["updates"]) if upd["updates"] else
              "no parameter moved by more than twice its standard error")
    heads = ["parameter", "name", "nominal", "updated", "change", "resolution (0-1)",
             "significant"]
    hs = upd.get("harmonic_spread")
    spread = (f"<p>The harmonics' and lines' model-form tolerance carries what the "
              f"update left uncertain: their spread over {hs['sigma_points']} sweeps at "
              f"the update's sigma points and the rotor before the update (median "
              f"{quantity(hs['median_m'], 'm')}, largest {quantity(hs['max_m'], 'm')}).</p>"
              if hs else "")
    bw = upd.get("backward_whirl_1x")
    whirl = (f"<p>{html.escape(bw['rule'][0].upper() + bw['rule'][1:])} (median over the "
             "speeds: " + ", ".join(f"{html.escape(k)} {quantity(v['median_m'], 'm')}"
                                    for k, v in bw["pairs"].items()) + ").</p>"
             if bw and bw["pairs"] else "")
    return (f"<h2>Nominal model updated (model error, not an effect)</h2>"
            f"<p>{html.escape(listed)}. Relative 1x mismatch at the training speeds "
            f"{100 * mm['before']:.2f} % before, {100 * mm['after']:.2f} % after. "
            f"{html.escape(upd['method'])}.</p>{table(rows, heads)}"
            "<p class=\"note\">Resolution: 1 - posterior/prior variance (0: the data say "
            "nothing about it). Pairs these data cannot separate (only a combination is "
            f"determined):</p><ul>{pairs or '<li>none</li>'}</ul>{spread}{whirl}")


def _passes_html(doc) -> str:
    """The report's section on two passes of the sweep (none without them)."""
    p = doc.get("passes")
    if not p:
        return ""
    where = table(
        ([value_range(*r["speed_range"], "rad/s"), r["order"], r["channel"], r["window"],
          f"{100 * r['share']:.1f} %", quantity(r.get("max_gap_m"), "m")]
         for r in p["where"][:10]),
        ["speeds", "order", "channel", "window", "share of the difference",
         "largest difference"],
        empty="No speed x order x channel cell differs significantly between the passes.")
    largest = table(
        ([quantity(r["speed"], "rad/s"), r["feature"], r["channel"], r["window"],
          quantity(r["first_m"], "m"), quantity(r["second_m"], "m"),
          quantity(r["difference_m"], "m"), quantity(r["z2"])] for r in p["largest"]),
        ["speed", "order", "channel", "window", "first pass", "second pass", "difference",
         "z\u00b2"], empty="")
    unmatched = p["unmatched_speeds"]
    left = "; ".join(f"{k} pass only: {', '.join(quantity(w, 'rad/s') for w in v)}"
                     for k, v in unmatched.items() if v)
    return (f"<h2>Two passes of the sweep</h2><p>{p['n_steps']} speed steps in both passes, "
            f"{p['n_features']} features compared model-free, the {p['n_tested']} shaft-order "
            "vectors (1/3x-3x) tested: beyond a dead band of "
            f"{100 * float(p['band_rtol']):.3g} % of each vector's size (what a rig does "
            "not repeat), their z\u00b2 is "
            f"{float(p['z2_ratio']):.3g} times what noise alone gives, a normal deviate of "
            f"{float(p['statistic']):.3g} against the floor "
            f"of {float(p['floor_sigmas']):.3g} (the normal point of the rule's false-alarm "
            "level): the passes "
            f"{'differ' if p['changed'] else 'agree'}. Line energies (one sum over the "
            "non-synchronous bands) are listed, not tested."
            + (f" Left out ({html.escape(left)})." if left else "") + "</p>"
            + where + largest)


def candidate_label(entry) -> str:
    """A ranking entry's name: its effects (or model error only) and the rotor reading
    it was fitted in, where it was not the rotor as given."""
    name = label(entry["effect"])
    reading = entry.get("rotor_reading")
    if reading is None:
        return name
    return f"{name} (in reading {reading!r})" if entry["effect"] else \
        f"rotor reading {reading!r} alone"


def _html(doc, figs, prov):
    verdict = doc["verdict"]
    rule = doc["settings"]["rule"]
    n_feat = doc.get("n_heldout_features")
    upd = doc.get("nominal_update") or {}
    unit_note = ("Gap per feature: the held-out excess of squared standardised differences "
                 "(measured minus simulated order vectors over their standard errors and "
                 "tolerances) above what noise gives, divided by the "
                 f"{n_feat or 'number of'} held-out features; dimensionless.")
    where = table(
        ([value_range(*r["speed_range"], "rad/s"), r["order"], r["channel"], r["window"],
          f"{100 * r['share']:.1f} %", quantity(r.get("max_gap_m"), "m")]
         for r in doc["where"][:15]),
        ["speeds", "order", "channel", "window", "share of the gap", "largest gap"],
        empty="No speed x order x channel cell differs significantly from the calibrated "
              "nominal model.")
    which = table(
        ([candidate_label(r), f"{100 * r['shrink']:.0f} %",
          quantity(r["heldout_gap_after"]),
          "; ".join(t for t in (effect_parameters(r["effect"], r["params"]),
                                "; ".join(f"{n}: {effect_parameters(n, v)}" for n, v in
                                          (r.get("model_error") or {}).items())) if t),
          "; ".join([*r["evidence"],
                     *filter(None, [discrete_text(r),
                                    linear_form_text(r, rule["min_gain"])])])]
         for r in doc["ranking"]),
        ["candidate", "held-out gap removed", "held-out excess after", "fitted parameters",
         "evidence"], empty="No candidate was fitted.")
    nuis = doc["nuisance"]
    nuis_rows = [[k, quantity(v, NUISANCE_UNITS.get(k, "")),
                  quantity(nuis.get("std", {}).get(f"nuisance.{k}",
                                                   nuis.get("std", {}).get(k)),
                           NUISANCE_UNITS.get(k, ""))]
                 for k, v in nuis["calibrated"].items()]
    noise_rows = [[k.replace("_", " "), quantity(v, "dB" if k.endswith("_db") else "m")]
                  for k, v in doc["noise"].items()]
    narx = ""
    if "narx" in doc:
        n = doc["narx"]
        narx = (f"<h2>NARX view ({html.escape(n['channel'])})</h2><p>Model of the measurement: "
                f"{html.escape(', '.join(n['terms_measured']))}.<br>Model of the simulation: "
                f"{html.escape(', '.join(n['terms_simulated']))}.<br>"
                f"{html.escape(n['reading'])}</p>")
    rule_rows = [[k, quantity(v) if isinstance(v, float) else html.escape(str(v))]
                 for k, v in rule.items()]
    imgs = "".join(figure(p) for p in figs.values())
    split = doc["split"]
    body = f"""<h2>Verdict: {html.escape(label(verdict))}</h2>
<p>{html.escape(verdict_text(doc))}</p>
<p class="note">{html.escape(unit_note)} Calibrated on {len(split['train_speeds'])} speeds,
held out {len(split['heldout_speeds'])}; {len(doc['channels'])} channel(s)
({html.escape(', '.join(doc['channels']))}), {quantity(doc['sampling']['fs_hz'], 'Hz')},
{doc['sampling']['samples_per_step']} samples per step.</p>
{_passes_html(doc)}
<h2>Where the model and the data disagree</h2>{where}
<h2>Which effect explains it</h2>{which}
{imgs}{narx}
{_update_html(upd)}
<h2>Nuisance calibration</h2>
<p class="note">Global scalars fitted before any effect (nominal 1, phase 0); the candidates
refit them with their own parameters.</p>
{table(nuis_rows, ["parameter", "calibrated", "standard error"])}
<h2>Noise, from the data</h2>{table(noise_rows, ["quantity", "value"])}
<h2>The verdict rule</h2><p class="note">Every value that decided the verdict
(sknarx.gap.VerdictRule; docs/gap.md, <i>The verdict rule</i>).</p>
{table(rule_rows, ["parameter", "value"])}"""
    return page("Sim-to-real gap diagnosis", body, prov)
