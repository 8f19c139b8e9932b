"""The words of a gap report, made from the same values that decided the verdict.

Every sentence here reads a ``diagnosis.json`` document (:mod:`sknarx.gap.document`)
and states its numbers with the test that used them: a shortfall is rendered from the
:class:`~sknarx.gap.candidate.Shortfall` the rule returned, so a sentence cannot say
one thing while the rule decided another. The command line prints the same sentences
(:func:`verdict_text`).
"""

from __future__ import annotations

from .._report import at_bound, quantity
from ..rotor import EFFECTS
from .candidate import Shortfall, percent

__all__ = ["label", "verdict_text", "shortfall_sentences", "effect_parameters",
           "alike_text", "passes_text", "setting_text", "linear_form_text", "reading_text",
           "discrete_text"]

#: the effects and their linear forms (a model error a candidate may carry), by name
_CLASSES = {**{c.linear_form.name: c.linear_form for c in EFFECTS.values()
               if c.linear_form is not None}, **EFFECTS}


def label(effect) -> str:
    """A verdict or candidate name as text (a pair joined by '+'; model error alone:
    'model error only')."""
    if isinstance(effect, str):
        return effect
    return " + ".join(effect) or "model error only"


_pct = percent


def _shortfall(entry: dict) -> Shortfall:
    return Shortfall(entry["test"], float(entry["value"]), float(entry["required"]))


def shortfall_sentences(subject: str, shortfalls) -> str:
    """``subject`` followed by each failed test's sentence
    (:meth:`~sknarx.gap.candidate.Shortfall.sentence`), joined."""
    parts = [_shortfall(s).sentence() if isinstance(s, dict) else s.sentence()
             for s in shortfalls]
    return f"{subject} " + ", and ".join(parts) + "." if parts else ""


def _floor(doc) -> tuple[float, float]:
    before = doc["gap_before"]
    floor = (before.get("floor") or {}).get("floor_per_feature")
    return float(before["per_feature"]), (float(floor) if floor is not None else None)


def _gap_clause(doc) -> str:
    """The gap before any candidate against its no-gap floor, as the rule compared them."""
    e0, floor = _floor(doc)
    if floor is None:
        return f"the held-out gap was {e0:.3g} per feature"
    level = 100 * (1 - float(doc["gap_before"]["floor"]["false_alarm"]))
    side = "within" if e0 <= floor else "above"
    return (f"the held-out gap was {e0:.3g} per feature, {side} the {floor:.3g} that the "
            f"sweep's own noise leaves at the {level:.0f} % level (its no-gap floor)")


def _set_aside_text(doc) -> str:
    """Each pair the rule set aside beside the verdict, with the test that did."""
    out = []
    for key in ("rival_pair", "pair_under_trigger"):
        note = doc.get(key)
        if note and "shortfall" in note:
            out.append(f" The pair {label(note['effect'])} removes {_pct(note['shrink'])} of "
                       f"the held-out gap but is not named: "
                       f"{_shortfall(note['shortfall']).sentence()}.")
    return "".join(out)


def setting_text(doc) -> str:
    """The verdict's caveat where the held-out speeds did not decide its discrete setting
    (a crack's station, a rub's disk)."""
    if doc.get("setting_decided", True):
        return ""
    level = 1 - float(doc["settings"]["rule"]["false_alarm"])
    return (" Where it acts is not decided by these data: over at least one other setting "
            f"the chosen one is preferred in fewer than {_pct(level)} of bootstrap "
            "resamples of the held-out speeds (see the ranking).")


def alike_text(verdict) -> str:
    """What the data cannot tell each named effect from (its class's ``alike``)."""
    names = [verdict] if isinstance(verdict, str) else list(verdict)
    return "".join(f" These data cannot tell the {n} from {EFFECTS[n].alike}."
                   for n in names if n in EFFECTS and EFFECTS[n].alike)


def _model_error_text(error) -> str:
    return "; ".join(f"{name}: {effect_parameters(name, values)}"
                     for name, values in (error or {}).items())


def reading_text(doc) -> str:
    """The verdict's rotor reading, where it was fitted in one (model error)."""
    reading = doc.get("rotor_reading")
    if not reading:
        return ""
    changes = ", ".join(f"{k} = {v:g}" for k, v in reading["changes"].items())
    entry = next((r for r in doc.get("rotor_readings", [])
                  if r["label"] == reading["label"]), {})
    alone = entry.get("heldout_gap_alone")
    updates = (entry.get("nominal_update") or {}).get("updates") or []
    return (f" Fitted in the rotor's reading {reading['label']!r} ({changes}), chosen on "
            "the held-out speeds over the rotor as given: model error, not part of the "
            "effect" + (f" (the reading alone leaves a held-out excess of {alone:.4g})"
                        if isinstance(alone, (int, float)) else "")
            + (f"; the reading's own nominal update: {'; '.join(updates)}." if updates
               else "."))


def passes_text(doc) -> str:
    """The sentence on two passes of the sweep (``passes``), empty without them."""
    p = doc.get("passes")
    if not p:
        return ""
    test = (f"beyond a dead band of {_pct(p['band_rtol'])} of each vector's size, their "
            f"shaft orders' z\u00b2 is {float(p['z2_ratio']):.3g} times what noise alone "
            f"gives, a normal deviate of {float(p['statistic']):.3g} against the "
            f"{float(p['floor_sigmas']):.3g} of the rule's false-alarm level")
    if not p["changed"]:
        return f" The two passes of the sweep agree ({test})."
    top = (p.get("largest") or [None])[0]
    most = (f", most at {top['feature']} on {top['channel']} at "
            f"{quantity(top['speed'], 'rad/s')}" if top else "")
    one = p.get("one_pass", {}).get("verdict")
    said = "" if one is None else f" The first pass alone: {label(one)}."
    return (f" The two passes of the sweep differ ({test}{most}): the rotor changed "
            "between them, which no time-invariant candidate of the library explains."
            + said)


def verdict_text(doc) -> str:
    """The verdict as sentences: what it names or why nothing is named, against the
    values the rule used."""
    verdict = doc["verdict"]
    gap = _gap_clause(doc)
    error = _model_error_text(doc.get("model_error"))
    passes = passes_text(doc)
    if verdict == "unexplained" and (doc.get("passes") or {}).get("changed"):
        return passes.strip()
    if verdict == "no-gap" and (error or doc.get("rotor_reading")):
        what = (f"the rotor's reading {doc['rotor_reading']['label']!r}"
                if doc.get("rotor_reading") else "a change of the linear rotor")
        return (f"No effect: {gap[0].lower() + gap[1:]}, and {what} explains it"
                + (f" ({error})" if error else "") + ". A change of linear parameters is "
                "model error, however much of the gap it removes." + passes)
    if verdict == "no-gap":
        upd = doc.get("nominal_update") or {}
        n = len(upd.get("updates") or [])
        return (f"No gap: {gap}, and no candidate passes the rule's tests of what is left"
                + (f"; {n} nominal parameter(s) updated (model error, listed below)" if n
                   else "") + "." + passes)
    if verdict == "unexplained":
        near = doc.get("closest")
        closest = shortfall_sentences(f" The closest candidate, {label(near['effect'])},",
                                      near.get("shortfalls", [])) if near else ""
        return (f"Unexplained: {gap}, and no candidate of the library explains it (the "
                f"best removes {_pct(doc['shrink'])} of it): an effect outside the library, "
                "or a nominal model further from the rig than its update allows."
                + closest + _set_aside_text(doc) + passes)
    band = doc.get("shrink_band")
    band_txt = f" (bootstrap 5-95 %: {_pct(band[0])} to {_pct(band[1])})" if band else ""
    above = doc.get("shrink_above_noise")
    e0, floor = _floor(doc)
    within = ""
    if floor is not None and e0 <= floor:
        rule = doc["settings"]["rule"]
        entry = next((r for r in doc["ranking"] if r["effect"] == verdict), {})
        within = (" It is named although the gap is within the floor because it passes the "
                  f"rule's tests of what is left: it removes {_pct(above)} of the gap above "
                  f"the noise (the rule asks {_pct(rule['min_shrink'])}) and "
                  f"{_pct(entry.get('log_shrink', float('nan')))} of its logarithm (the rule "
                  f"asks {_pct(rule['min_log_shrink'])}).") if above is not None else ""
    above_txt = (f", {_pct(above)} of what lies above the noise" if above is not None
                 and abs(float(above) - float(doc["shrink"])) >= 0.005 else "")
    return (f"{label(verdict)} removes {_pct(doc['shrink'])} of the held-out gap"
            f"{band_txt}{above_txt}; {gap}." + within
            + (f" Fitted with it, as model error (a change of the linear rotor, not an "
               f"effect): {error}." if error else "")
            + reading_text(doc) + setting_text(doc) + _set_aside_text(doc)
            + alike_text(verdict) + passes)


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


def _excess(value) -> str:
    """A held-out excess as text (a diverged fit's is 'inf')."""
    return f"{value:.4g}" if isinstance(value, (int, float)) else str(value)


def linear_form_text(entry, min_gain) -> str:
    """What the effect-or-model-error test found for a ranking entry: the candidate it
    replaced, or each linear form it was tested against and whether the member removed
    ``min_gain`` of what that form leaves."""
    parts = []
    if r := entry.get("replaces"):
        parts.append(f"replaces {label(r['effect'])}: its {r['member']} did no more than "
                     f"this linear change (held-out excess {_excess(r['heldout_gap_after'])} "
                     "with it)")
    after = entry.get("heldout_gap_after")
    for t in entry.get("linear_form_tests", []):
        left = t["heldout_gap_after"]
        if isinstance(after, (int, float)) and isinstance(left, (int, float)) and left > 0:
            removed = 1.0 - after / left
            verdict = ("an effect" if removed >= min_gain else
                       f"model error, left out of the verdict (the rule asks "
                       f"{_pct(min_gain)})")
            share = f"; it removes {_pct(removed)} of what the form leaves: {verdict}"
        else:
            share = ""
        parts.append(f"{t['member']} tested against its linear form {t['linear_form']} "
                     f"(which leaves {_excess(left)}){share}")
    return "; ".join(parts)


def discrete_text(entry) -> str:
    """How well the held-out speeds told a candidate's discrete settings apart."""
    rows = entry.get("discrete_settings")
    if not rows:
        return ""

    def name(setting):
        return ", ".join(f"{n} {v}" for n, fields in setting.items() for v in fields.values())

    def share(r):
        v = r.get("chosen_preferred_share")
        return "" if v is None else f" (the first preferred in {_pct(v)} of resamples)"

    decided = entry.get("setting_decided")
    return ("held-out excess by setting: "
            + "; ".join(f"{name(r['setting'])} {_excess(r['heldout_gap_after'])}{share(r)}"
                        for r in rows)
            + ("" if decided is None else
               "; setting decided" if decided else "; setting not decided by the data"))
