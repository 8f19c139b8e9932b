"""A verdict as ``diagnosis.json`` states it: the same values that decided it.

Both front ends end here: the :class:`~sknarx.gap.candidate.Verdict` of the rule, the
ranking and the held-out tables become the document's verdict keys (``verdict``,
``shrink``, ``shrink_band``, ``gap_after``, ``regions_after``, ``closest``,
``rival_pair``, ``pair_under_trigger``, ...; ``docs/gap.md``, *Output*). A second pass
that shows the rotor changed overrides the verdict (:func:`with_passes`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .candidate import Candidate, NoiseFloor, Verdict
from .evidence import bootstrap_shrink, regions_after

__all__ = ["verdict_entries", "ranking_entries", "with_passes"]

#: a verdict's entries that describe the fit of the effect it names
NAMED_FIT = ("shrink_band", "gap_after", "regions_after", "setting_decided", "model_error",
             "rotor_reading", "shrink_above_noise")


def ranking_entries(ranking: list, floor: NoiseFloor | None, n_features: int) -> list:
    """The ranking as it goes into the document, best first."""
    return [c.to_entry(floor, n_features) for c in ranking]


def _pair_note(pair: Candidate, shortfall, verdict: Verdict, ranking, rule, n: int):
    """The document's entry for a pair the rule set aside: its key and value."""
    base = {"effect": pair.label, "shrink": pair.shrink,
            "heldout_gap_after": pair.heldout_after, "shortfall": shortfall.to_dict()}
    if shortfall.test == "rival":
        alone = rule.shrinks_alone(ranking, verdict.floor, n)
        return "rival_pair", {**base, "pair_rival_shrink": rule.min_shrink,
                              "members_alone": {m: alone.get(m) for m in pair.effects}}
    single = verdict.candidate
    left = single.heldout_after if single is not None else float("nan")
    return "pair_under_trigger", {
        **base, "single": single.label if single is not None else None,
        "single_leaves_per_feature": left / n,
        "removes_of_single": 1.0 - pair.heldout_after / left if left > 0 else 0.0,
        "pair_trigger": rule.pair_trigger}


def verdict_entries(verdict: Verdict, ranking: list, cmp0: pd.DataFrame, where: list, rule,
                    budget, n_features: int) -> dict:
    """The document's verdict keys from ``verdict`` (the rule's answer on ``ranking``):
    ``verdict`` and ``shrink`` always; with a named effect its ``shrink_above_noise``,
    bootstrap ``shrink_band``, ``gap_after``, ``regions_after`` and, where it has them,
    ``model_error`` and ``setting_decided``; for ``unexplained`` the candidate judged and
    the tests it failed (``closest``); a pair set aside by the trigger or the rival
    test, beside a named or unexplained verdict (``pair_under_trigger``,
    ``rival_pair``)."""
    n = max(int(n_features), 1)
    judged = verdict.candidate
    if verdict.outcome == "no-gap" and verdict.named is None:
        return {"verdict": "no-gap", "shrink": 0.0}
    notes = {}
    for pair, shortfall in verdict.set_aside:
        key, value = _pair_note(pair, shortfall, verdict, ranking, rule, n)
        notes[key] = value
    if verdict.outcome == "unexplained":
        out = {"verdict": "unexplained",
               "shrink": max(ranking[0].shrink, 0.0) if ranking else 0.0, **notes}
        if judged is not None:
            out["closest"] = {
                "effect": judged.label, "shrink": judged.shrink,
                "shrink_above_noise": judged.shrink_above(verdict.floor, n),
                "log_shrink": judged.log_shrink, "heldout_gap_after": judged.heldout_after,
                "short_of": [s.test for s in verdict.shortfalls],
                "shortfalls": [s.to_dict() for s in verdict.shortfalls],
                "min_shrink": rule.min_shrink, "min_log_shrink": rule.min_log_shrink}
        return out
    cmp = judged.cmp
    gap_after = {"heldout_excess": judged.heldout_after,
                 "rms_gap_m": float(np.sqrt(np.mean(cmp["gap"] ** 2)))}
    extra = {"model_error": judged.details["model_error"]} \
        if judged.details.get("model_error") else {}
    extra.update(notes)
    if not judged.effects:  # model error alone explains the gap: no effect
        return {"verdict": "no-gap", "shrink": 0.0, "gap_after": gap_after, **extra}
    if "setting_decided" in judged.details:
        extra["setting_decided"] = judged.details["setting_decided"]
    return {"verdict": judged.label, "shrink": judged.shrink,
            "shrink_above_noise": judged.shrink_above(verdict.floor, n),
            "shrink_band": bootstrap_shrink(cmp0, cmp, budget.n_bootstrap,
                                            budget.random_state),
            "gap_after": gap_after, "regions_after": regions_after(where, cmp, cmp0),
            **extra}


def with_passes(result, comparison):
    """A diagnosis (:class:`~sknarx.gap.GapDiagnosis`) with the test of two passes of its
    sweep (:class:`~sknarx.gap.passes.PassComparison`; None: ``result`` as it is).

    The document gains ``passes``. Where the passes differ the rotor changed between
    them, which no time-invariant candidate of the library explains: the verdict
    becomes ``unexplained``, and what the first pass alone concluded moves to
    ``passes["one_pass"]`` (its table after the fit to ``tables["after_one_pass"]``).
    The ranking stays: it is the best time-invariant reading of the first pass.
    """
    if comparison is None:
        return result
    doc = result.document
    entry = comparison.to_dict()
    if comparison.changed:
        entry["one_pass"] = {"verdict": doc["verdict"],
                             **{k: doc.pop(k) for k in NAMED_FIT if k in doc}}
        doc["verdict"] = "unexplained"
        if "after" in result.tables:
            result.tables["after_one_pass"] = result.tables.pop("after")
    doc["passes"] = entry
    return result
