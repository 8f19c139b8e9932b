"""diagnosis.json, figures and report.html of a gap diagnosis."""

from __future__ import annotations

import html
import json
from pathlib import Path
from statistics import NormalDist

import numpy as np

from .._report import at_bound, figure, page, provenance, quantity, table, value_range
from ..io import json_safe, write_atomic, write_text_atomic
from ..plotting import plt, save
from ..rotor import EFFECTS
from .calibration import NUISANCE_UNITS
from .core import passes_form_test, removed_beyond_form
from .features import NONSYNC_LABELS

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
                                f"Held-out gap with the verdict ({_label(result['verdict'])})")
    if result["ranking"]:
        fig, ax = plt.subplots(figsize=(6, 3))
        names = [_label(r["effect"]) for r in result["ranking"]]
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


def _label(effect):
    return effect if isinstance(effect, str) else " + ".join(effect)


#: the effects and their linear forms (a model error a candidate may carry), by name
_CLASSES = {**{c.linear_form.name: c.linear_form for c in EFFECTS.values()
               if c.linear_form is not None}, **EFFECTS}


def _candidate_label(entry) -> str:
    """A ranking entry's name in the report: its effects, or model error only, and the
    rotor reading it was fitted in where it was not the rotor as given."""
    name = _label(entry["effect"])
    reading = entry.get("rotor_reading")
    if reading is None:
        return name or "model error only"
    return f"{name} (in reading {reading!r})" if name else f"rotor reading {reading!r} alone"


def _changes_text(changes) -> str:
    """A reading's parameter changes as text."""
    return ", ".join(f"{k} = {v:g}" for k, v in changes.items())


def _reading_text(doc) -> str:
    """The verdict's rotor reading, where it was fitted in one (model error)."""
    reading = doc.get("rotor_reading")
    if not reading:
        return ""
    entry = next((r for r in doc.get("rotor_readings", [])
                  if r["label"] == reading["label"]), {})
    alone = entry.get("heldout_gap_alone")
    updates = (entry.get("nominal_update") or {}).get("updates") or []
    return (f" Fitted in the rotor's reading {reading['label']!r} "
            f"({_changes_text(reading['changes'])}), chosen on the held-out speeds over "
            "the rotor as given: model error, not part of the effect"
            + (f" (the reading alone leaves a held-out excess of {alone:.4g})"
               if isinstance(alone, (int, float)) else "")
            + (f"; the reading's own nominal update: {'; '.join(updates)}." if updates
               else "."))


def _model_error_text(error) -> str:
    """A candidate's model error (linear forms of members that were no effect)."""
    return "; ".join(f"{name}: {effect_parameters(name, values)}"
                     for name, values in (error or {}).items())


def _finite(value) -> bool:
    """Whether ``value`` is a finite number (not a diverged fit's 'inf')."""
    return isinstance(value, (int, float)) and bool(np.isfinite(value))


def _excess(value) -> str:
    """A held-out excess (dimensionless) as text; a diverged fit's is 'inf' (a string
    once the document is JSON-safe)."""
    return f"{value:.4g}" if isinstance(value, (int, float)) else str(value)


def _discrete_text(entry) -> str:
    """How well the held-out speeds told a candidate's discrete settings apart."""
    rows = entry.get("discrete_settings")
    if not rows:
        return ""

    def label(setting):
        return ", ".join(f"{name} {v}" for name, fields in setting.items()
                         for v in fields.values())

    def share(r):
        v = r.get("chosen_preferred_share")
        return "" if v is None else f" (the first preferred in {100 * v:.0f} % of resamples)"

    decided = entry.get("setting_decided")
    return ("held-out excess by setting: "
            + "; ".join(f"{label(r['setting'])} {_excess(r['heldout_gap_after'])}{share(r)}"
                        for r in rows)
            + ("" if decided is None else
               "; setting decided" if decided else "; setting not decided by the data"))


def _undecided_text(doc) -> str:
    """The verdict's caveat where the held-out speeds did not decide its discrete
    setting (a crack's station, a rub's disk)."""
    if doc.get("setting_decided", True):
        return ""
    level = (doc.get("settings") or {}).get("decided_setting_support")
    share = f"{100 * level:.0f} % of" if level is not None else "enough"
    return (" Where it acts is not decided by these data: over at least one other "
            f"setting, the chosen one is preferred in fewer than {share} bootstrap "
            "resamples of the held-out speeds (see the ranking's evidence).")


def alike_text(verdict) -> str:
    """What the data cannot tell each named effect from (its class's ``alike``), for the
    headline of a verdict that names effects."""
    names = [verdict] if isinstance(verdict, str) else list(verdict)
    return "".join(f" These data cannot tell the {n} from {EFFECTS[n].alike}."
                   for n in names if n in EFFECTS and EFFECTS[n].alike)


def closest_text(doc) -> str:
    """Why the candidate an ``unexplained`` verdict judged was not named
    (``sknarx.gap.core.closest``), as a sentence."""
    near = doc.get("closest")
    if not near or not near["short_of"]:
        return ""
    lead = (f" The closest candidate, {_label(near['effect'])}, removes "
            f"{100 * near['shrink']:.0f} % of the held-out gap")
    above = near.get("shrink_above_noise", near["shrink"])
    if abs(above - near["shrink"]) >= 0.005:
        # the verdict judges the share of the gap above the effect-free noise (its
        # median: a sweep whose own noise is under it can have more than all removed)
        lead += (" (more than all of what is above the effect-free noise)" if above > 1
                 else f" ({100 * above:.0f} % of what is above the effect-free noise)")
    need, log = 100 * near["min_shrink"], 100 * near["log_shrink"]
    need_log = 100 * near["min_log_shrink"]
    if near["short_of"] == ["shrink"]:
        return f"{lead}, where a named effect needs {need:.0f} % of that."
    if near["short_of"] == ["breadth"]:
        return (f"{lead} but only {log:.0f} % of its logarithm, where a named effect needs "
                f"{need_log:.0f} %: it matches the largest features, not the many others.")
    return (f"{lead} and {log:.0f} % of its logarithm, where a named effect needs "
            f"{need:.0f} % and {need_log:.0f} %.")


def _rival_text(doc) -> str:
    """The verdict's note where the rival test set a pair aside
    (``sknarx.gap.core.rival_pair_set_aside``)."""
    aside = doc.get("rival_pair")
    if not aside:
        return ""
    alone = ", ".join(f"{name} {100 * float(v):.0f} %"
                      for name, v in aside["members_alone"].items())
    return (f" The pair {_label(aside['effect'])} removed more "
            f"({100 * float(aside['shrink']):.0f} %), but each of its members alone removes "
            f"at least {100 * float(aside['pair_rival_shrink']):.0f} % of the gap ({alone}): "
            "two rival readings of one signature, not two effects, so the pair is not "
            "named.")


def under_trigger_text(doc) -> str:
    """The verdict's note where the pair trigger kept a ranked pair from being named
    (``sknarx.gap.core.pair_under_trigger``)."""
    under = doc.get("pair_under_trigger")
    if not under:
        return ""
    return (f" The pair {_label(under['effect'])} is ranked and removes "
            f"{100 * float(under['removes_of_single']):.0f} % of what {_label(under['single'])} "
            f"alone leaves, but {_label(under['single'])} already leaves "
            f"{float(under['single_leaves_per_feature']):.3g} per feature, no more than the "
            f"{float(under['pair_trigger']):.3g} a second effect must explain to be named: "
            "a lead to check, not a finding.")


def _linear_form_text(entry, gain=None) -> str:
    """What the effect-or-model-error test (``sknarx.gap.core.search``, step 4) found for
    a ranking entry: the candidate it replaced, or the linear forms it beat, with the
    share of what each form leaves that the member removes; with ``gain`` (the settings'
    ``linear_form_gain``), whether that was enough for the verdict to consider it."""
    parts = []
    if r := entry.get("replaces"):
        parts.append(f"replaces {_label(r['effect'])}: its {r['member']} did no more than "
                     f"this linear change (held-out excess {_excess(r['heldout_gap_after'])} "
                     f"with it)")
    for t in entry.get("linear_form_tests", []):
        share, kept = "", True
        # a diverged fit's excess is 'inf' in a JSON-safe document: no share then
        if _finite(entry.get("heldout_gap_after")) and _finite(t["heldout_gap_after"]):
            share = f", {100 * removed_beyond_form(entry, t):.0f} % of which it removes"
            kept = passes_form_test(entry, t, gain)
        outcome = "an effect" if kept else "model error"
        left_out = "" if kept else (f", under the {100 * gain:.0f} % an effect must "
                                    "remove: left out of the verdict")
        parts.append(f"{t['member']} tested against its linear form {t['linear_form']}: "
                     f"{outcome} (the linear form leaves {_excess(t['heldout_gap_after'])}"
                     f"{share}{left_out})")
    return "; ".join(parts)


def effect_parameters(effect, params) -> str:
    """Fitted parameters with units; a value on its search bound is flagged."""
    names = [effect] if isinstance(effect, str) else list(effect)
    groups = [params] if isinstance(effect, str) else list(params)
    parts = []
    for name, values in zip(names, groups, strict=False):
        cls = _CLASSES.get(name)
        for key, value in values.items():
            if isinstance(value, dict) and "1x_m" in value:  # a probe's runout vectors
                parts.append(f"{key}: 1x {quantity(value['1x_m'], 'm')} at "
                             f"{value['1x_deg']:.0f} deg, 2x {quantity(value['2x_m'], 'm')} "
                             f"at {value['2x_deg']:.0f} deg")
                continue
            if not isinstance(value, (int, float)):
                parts.append(f"{key} {value}")
                continue
            unit = cls.units.get(key, "") if cls is not None else ""
            text = f"{key} {quantity(value, unit)}"
            if cls is not None and key in cls.bounds:
                lo, hi, scale = cls.bounds[key]
                side = at_bound(value, lo, hi, scale)
                if side:
                    bound = lo if side == "lower" else hi
                    text += f" (AT {side.upper()} BOUND {quantity(bound, unit)})"
            parts.append(text)
        if len(names) > 1:
            parts[-1] += f" [{name}]"
    return "; ".join(parts)


def _by_order(doc) -> dict:
    """The per-order test of the gap before any effect (``gap_before.by_order``); empty
    where the front end has none (the order-domain front end, a document without it)."""
    return (doc.get("gap_before") or {}).get("by_order") or {}


def _orders_text(doc) -> str:
    """The orders whose held-out features exceeded their own floor (a sweep sent to the
    candidates with its mean over every feature under the no-gap floor), as a sentence."""
    over = {k: v for k, v in _by_order(doc).items() if v.get("over_floor")}
    if not over:
        return ""
    parts = [f"the {v['n']} held-out {k} features (mean z\u00b2 {v['mean_z2']:.3g} against "
             f"their floor {v['floor_z2']:.3g}, dimensionless)" for k, v in over.items()]
    return (" On their own, " + " and ".join(parts) + " exceed the effect-free level, so "
            "the candidates were fitted although the mean over every feature is within "
            "the no-gap floor.")


def _under_floor_text(doc) -> str:
    """Why an effect is named for a sweep whose gap was within the no-gap floor (every
    order within its own), as a sentence: only ``attribute_below_floor`` names one
    there. Empty for a sweep above the floor."""
    settings = doc["settings"]
    before = float(doc["gap_before"]["per_feature"])
    if (before > float(settings["no_gap_per_feature"])
            or any(v.get("over_floor") for v in _by_order(doc).values())):
        return ""
    noise = settings.get("noise_per_feature")
    left = ("what is left" if noise is None else
            f"what is left above the effect-free noise ({float(noise):.3g} per feature)")
    return (" Under the floor, it is named because it removes at least "
            f"{100 * float(settings['min_shrink']):.0f} % of {left} and "
            f"{100 * float(settings['min_log_shrink']):.0f} % of its logarithm "
            "(attribute_below_floor).")


def _orders_table(doc) -> str:
    """Each tested order's held-out mean z2 against its own floor, as an HTML table (empty
    where the front end has no per-order test)."""
    rows = [[k, v["n"], f"{v['mean_z2']:.3g}",
             "-" if v.get("floor_z2") is None else f"{v['floor_z2']:.3g}",
             "yes" if v.get("over_floor") else "no"] for k, v in _by_order(doc).items()]
    if not rows:
        return ""
    return ("<h3>Each order against its own floor</h3><p class=\"note\">Mean squared "
            "standardised difference (z\u00b2, dimensionless) of each order's held-out "
            "features after the nuisance calibration; a sweep under the no-gap floor goes to "
            "the candidates when any order exceeds its own.</p>"
            + table(rows, ["order", "held-out features", "mean z\u00b2", "floor",
                           "over its floor"]))


def _one_pass_text(doc) -> str:
    """What the first pass alone concluded, where the passes test overrode it."""
    one = (doc.get("passes") or {}).get("one_pass")
    if not one:
        return ""
    v = one["verdict"]
    if v == "no-gap":
        said = "no-gap: its gap is within the floor, the change is not"
    elif v == "unexplained":
        said = "unexplained as well"
    else:
        said = (f"{_label(v)}, removing {100 * float(doc['shrink']):.0f} % of its held-out "
                "gap, a time-invariant reading of one pass of a rotor that changed")
    return f" The first pass alone: {said}."


def _band(p) -> str:
    """The pass test's dead band in words (its share of a vector's size; older documents
    without it: the 1 % the test then used as a tolerance)."""
    return (f"{100 * float(p.get('band_rtol', 0.01)):.3g} % of each vector's size (and a "
            "moved step's slope)")


def passes_text(doc) -> str:
    """The verdict's sentence on two passes of the sweep (``passes``), empty without
    them."""
    p = doc.get("passes")
    if not p:
        return ""
    test = (f"beyond a dead band of {_band(p)}, their shaft orders' z\u00b2 is "
            f"{float(p['z2_ratio']):.3g} times what noise alone gives, a normal deviate of "
            f"{float(p['statistic']):.3g} against the floor of {float(p['floor_sigmas']):.3g}")
    if not p["changed"]:
        return f" The two passes of the sweep agree ({test})."
    top = (p.get("largest") or [None])[0]
    most = (f", most at {top['feature']} on {top['channel']} at "
            f"{quantity(top['speed'], 'rad/s')} ({quantity(top['first_m'], 'm')} against "
            f"{quantity(top['second_m'], 'm')})" if top else "")
    return (f" The two passes of the sweep differ ({test}{most}): the rotor changed "
            "between them, by an effect that varies in time (a thermal bow relaxing, a "
            "crack growing, a joint working loose) or by a response that depends on how "
            "each speed was reached (a rub or a clearance jumping between branches). No "
            "candidate of the library, each time-invariant, explains that."
            + _one_pass_text(doc))


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
        empty="No speed x order x channel cell differs significantly (z^2 > 9) between "
              "the passes.")
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
            f"vectors (1/3x-3x) tested: beyond a dead band of {_band(p)} (what a rig does "
            "not repeat), their z\u00b2 is "
            f"{float(p['z2_ratio']):.3g} times what noise alone gives, a normal deviate of "
            f"{float(p['statistic']):.3g} against the floor "
            f"of {float(p['floor_sigmas']):.3g} (a normal's "
            f"{100 * NormalDist().cdf(float(p['floor_sigmas'])):.0f} % point): the passes "
            f"{'differ' if p['changed'] else 'agree'}. Line energies (one sum over the "
            "non-synchronous bands) are listed, not tested."
            + (f" Left out ({html.escape(left)})." if left else "") + "</p>"
            + where + largest)


def _html(doc, figs, prov):
    verdict = doc["verdict"]
    floor = float(doc["settings"]["no_gap_per_feature"])
    gain = doc["settings"].get("linear_form_gain")
    before = float(doc["gap_before"]["per_feature"])
    n_feat = doc.get("n_heldout_features")
    upd = doc.get("nominal_update") or {}
    updated = "updated " if upd else ""
    error = _model_error_text(doc.get("model_error"))
    reading = doc.get("rotor_reading")
    if verdict == "no-gap" and reading:
        headline = (f"The held-out gap, {before:.3g} per feature against the no-gap floor "
                    f"{floor:.3g}, is the rotor's reading {reading['label']!r} "
                    f"({_changes_text(reading['changes'])}), not an effect: model error, "
                    "which the held-out speeds chose over the rotor as given and over "
                    "every candidate." + (f" Fitted with it: {error}." if error else ""))
    elif verdict == "no-gap" and error:
        headline = (f"The held-out gap, {before:.3g} per feature against the no-gap floor "
                    f"{floor:.3g}, is a change of the linear rotor, not an effect: "
                    f"{error}. A change of linear parameters is model error, however much "
                    "of the gap it removes.")
    elif verdict == "no-gap":
        headline = (f"The held-out gap after nuisance calibration, {before:.3g} per feature, "
                    f"is within the no-gap floor of {floor:.3g} (the 99 % level of "
                    f"effect-free sweeps): the {updated}nominal model explains these data"
                    + (f" ({len(upd['updates'])} parameter(s) updated, listed below)."
                       if upd.get("updates") else "."))
    elif verdict == "unexplained" and (doc.get("passes") or {}).get("changed"):
        headline = passes_text(doc).strip()
    elif verdict == "unexplained":
        headline = (f"The held-out gap, {before:.3g} per feature against the no-gap floor "
                    f"{floor:.3g}, is real, but no candidate removes enough of it (best: "
                    f"{100 * float(doc['shrink']):.0f} %): an effect outside the library, or "
                    "a nominal model further from the rig than the nuisance scalars allow."
                    + closest_text(doc) + _orders_text(doc) + _rival_text(doc)
                    + under_trigger_text(doc) + passes_text(doc))
    else:
        band = doc.get("shrink_band")
        band_txt = (f" (bootstrap 5-95 %: {100 * band[0]:.0f}-{100 * band[1]:.0f} %)"
                    if band else "")
        headline = (f"{_label(verdict)} removes {100 * float(doc['shrink']):.0f} % of the "
                    f"held-out gap{band_txt}; the gap was {before:.3g} per feature against "
                    f"the no-gap floor {floor:.3g}." + _under_floor_text(doc)
                    + (f" Fitted with it, as model error (a change of the linear rotor, "
                       f"not an effect): {error}." if error else "")
                    + _reading_text(doc)
                    + _orders_text(doc) + _undecided_text(doc) + _rival_text(doc)
                    + under_trigger_text(doc) + alike_text(verdict) + passes_text(doc))
    if verdict == "no-gap":
        headline += passes_text(doc)
    unit_note = ("Gap per feature: the held-out excess of squared standardised differences "
                 "(measured minus simulated order vectors over their standard errors) above "
                 f"what noise gives, divided by the {n_feat or 'number of'} held-out features; "
                 "dimensionless.")
    where = table(
        ([value_range(*r["speed_range"], "rad/s"), r["order"], r["channel"], r["window"],
          f"{100 * r['share']:.1f} %", quantity(r.get("max_gap_m"), "m")]
         for r in doc["where"][:15]),
        ["speeds", "order", "channel", "window", "share of the gap", "largest gap"],
        empty="No speed x order x channel cell differs significantly (z^2 > 9) from the "
              "calibrated nominal model.")
    which = table(
        ([_candidate_label(r), f"{100 * r['shrink']:.0f} %",
          quantity(r["heldout_gap_after"]),
          "; ".join(t for t in (effect_parameters(r["effect"], r["params"]),
                                _model_error_text(r.get("model_error"))) if t),
          "; ".join([*r["evidence"], *filter(None, [_discrete_text(r),
                                                     _linear_form_text(r, gain)])])]
         for r in doc["ranking"]),
        ["candidate", "held-out gap removed", "held-out excess after", "fitted parameters",
         "evidence"],
        empty=("No candidate was fitted: the gap is within the no-gap floor, so there is "
               "nothing for an effect to explain." if verdict == "no-gap" else
               "No candidate was fitted."))
    nuis = doc["nuisance"]
    nuis_rows = [[k, quantity(v, NUISANCE_UNITS.get(k, "")),
                  quantity(nuis.get("std", {}).get(f"nuisance.{k}",
                                                   nuis.get("std", {}).get(k)),
                           NUISANCE_UNITS.get(k, ""))]
                 for k, v in nuis["calibrated"].items()]
    noise = doc["noise"]
    noise_rows = [[k.replace("_", " "), quantity(v, "dB" if k.endswith("_db") else "m")]
                  for k, v in noise.items()]
    narx = ""
    if "narx" in doc:
        n = doc["narx"]
        narx = (f"<h2>NARX view ({html.escape(n['channel'])})</h2><p>Model of the measurement: "
                f"{html.escape(', '.join(n['terms_measured']))}.<br>Model of the simulation: "
                f"{html.escape(', '.join(n['terms_simulated']))}.<br>"
                f"{html.escape(n['reading'])}</p>")
    imgs = "".join(figure(p) for p in figs.values())
    split = doc["split"]
    body = f"""<h2>Verdict: {html.escape(_label(verdict))}</h2><p>{html.escape(headline)}</p>
<p class="note">{html.escape(unit_note)} Calibrated on {len(split['train_speeds'])} speeds,
held out {len(split['heldout_speeds'])}; {len(doc['channels'])} channel(s)
({html.escape(', '.join(doc['channels']))}), {quantity(doc['sampling']['fs_hz'], 'Hz')},
{doc['sampling']['samples_per_step']} samples per step.</p>
{_passes_html(doc)}
<h2>Where the model and the data disagree</h2>{where}{_orders_table(doc)}
<h2>Which effect explains it</h2>{which}
{imgs}{narx}
{_update_html(upd)}
<h2>Nuisance calibration</h2>
<p class="note">Global scalars fitted before any effect (nominal 1, phase 0); the candidates
refit them with their own parameters.</p>
{table(nuis_rows, ["parameter", "calibrated", "standard error"])}
<h2>Noise, from the data</h2>{table(noise_rows, ["quantity", "value"])}"""
    return page("Sim-to-real gap diagnosis", body, prov)
