"""diagnosis.json, figures and report.html of a gap diagnosis."""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from ..io import json_safe
from ..plotting import plt, save, to_data_uri
from .features import NONSYNC_LABELS

FEATURE_ORDER = ["1/3x", "1/2x", "1x", "2x", "3x", *NONSYNC_LABELS]


def heatmap(cmp, path, title):
    """log10(1 + z2) over speed x feature, one panel per channel and window."""
    chans = sorted(cmp.channel.unique())
    wins = ["transient", "steady"]
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_gap_outputs(result: dict, out, command: str, narx: dict | None = None) -> dict:
    from .._version import __version__

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tables = result.get("_tables", {})
    figs = {}
    if "all" in tables:
        figs["map"] = heatmap(tables["all"], out / "gap_map.png",
                              "Gap map after nuisance calibration (all speeds)")
    if "after" in tables:
        figs["after"] = heatmap(tables["after"], out / "gap_map_after.png",
                                f"Held-out gap with the verdict ({result['verdict']})")
    if result["ranking"]:
        fig, ax = plt.subplots(figsize=(6, 3))
        names = [r["effect"] if isinstance(r["effect"], str) else "+".join(r["effect"])
                 for r in result["ranking"]]
        ax.barh(names[::-1], [max(r["shrink"], 0) for r in result["ranking"]][::-1])
        ax.set(xlabel="share of the held-out gap removed", xlim=(0, 1))
        figs["ranking"] = save(fig, out / "ranking.png")
    doc = json_safe({k: v for k, v in result.items() if not k.startswith("_")})
    doc["sknarx_version"] = __version__
    doc["command"] = command
    if narx is not None:
        doc["narx"] = json_safe(narx)
    (out / "diagnosis.json").write_text(json.dumps(doc, indent=1))
    (out / "report.html").write_text(_html(doc, figs))
    return doc


def _html(doc, figs):
    verdict = doc["verdict"]
    vtxt = verdict if isinstance(verdict, str) else " + ".join(verdict)
    def label(e):
        return e if isinstance(e, str) else " + ".join(e)

    rows = "".join(
        f"<tr><td>{html.escape(label(r['effect']))}</td><td>{r['shrink']:.2f}</td><td>{r['heldout_gap_after']:.3g}</td>"
        f"<td>{html.escape(json.dumps(r['params']))}</td>"
        f"<td>{html.escape('; '.join(r['evidence']))}</td></tr>"
        for r in doc["ranking"])
    where = "".join(
        f"<tr><td>{r['speed_range'][0]:.1f}-{r['speed_range'][1]:.1f}</td><td>{r['order']}</td>"
        f"<td>{r['channel']}</td><td>{r['window']}</td><td>{100 * r['share']:.1f} %</td></tr>"
        for r in doc["where"][:15])
    imgs = "".join(f'<figure><img src="{to_data_uri(p)}"></figure>' for p in figs.values())
    narx = ""
    if "narx" in doc:
        n = doc["narx"]
        narx = (f"<h2>NARX view ({n['channel']})</h2><p>Measured model: "
                f"{html.escape(', '.join(n['terms_measured']))}.<br>Simulated model: "
                f"{html.escape(', '.join(n['terms_simulated']))}.<br>{html.escape(n['reading'])}"
                "</p>")
    band = doc.get("shrink_band")
    band_txt = f" (5-95 %: {band[0]:.2f}-{band[1]:.2f})" if band else ""
    css = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
           "table{border-collapse:collapse;font-size:0.85em}td,th{border:1px solid #ccc;"
           "padding:3px 6px}img{max-width:100%}")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>sknarx gap diagnosis
</title><style>{css}</style></head><body><h1>Sim-to-real gap diagnosis</h1>
<p>sknarx {html.escape(doc['sknarx_version'])}; command <code>{html.escape(doc['command'])}
</code>.</p>
<h2>Verdict: {html.escape(vtxt)}</h2>
<p>Held-out gap removed by the verdict: <b>{100 * doc['shrink']:.0f} %</b>{band_txt}.
Gap before (after nuisance calibration), per held-out feature:
{doc['gap_before']['per_feature']:.3g} (noise level: about 0.7).</p>
<h2>Where</h2><table><tr><th>speed (rad/s)</th><th>order</th><th>channel</th>
<th>window</th><th>share of gap</th></tr>{where}</table>
<h2>Which</h2><table><tr><th>candidate</th><th>shrink</th><th>held-out gap after</th>
<th>calibrated parameters</th><th>evidence</th></tr>{rows}</table>
{imgs}{narx}
<h2>Nuisance calibration and noise</h2><pre>{html.escape(json.dumps(
        {"nuisance": doc['nuisance'], "noise": doc['noise'], "split": doc['split']},
        indent=1))}</pre></body></html>"""
