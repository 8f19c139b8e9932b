"""Blind trials: which are drawn, and one trial diagnosed and logged as a record.

A run draws its trials by :func:`plan` from consecutive seeds: rounds of two effect-free
sweeps, every library effect, two pairs and every out-of-library effect the family can
express, interleaved so that a short run covers every category. :func:`run_trial`
simulates one on its family's plant (:mod:`validation.plants.families`), measured in two
passes (the coast-down after the run-up), diagnoses it with the package as installed and
returns the record :mod:`validation.score` reads.
"""

from __future__ import annotations

import time

import numpy as np

from .plants.families import (
    LIB,
    MEASUREMENT,
    OUT,
    PAIRS,
    SPEEDS,
    UNSUPPORTED,
    feature_gap,
    make_family_trial,
    measure,
    simulate,
)

__all__ = ["plan", "run_trial", "member_gaps", "PLANT_FAILURES"]


#: how a plant's own run fails (ROSS's Newton iteration raises a bare Warning): such a
#: trial is logged as skipped, not diagnosed on a sweep that is not there
PLANT_FAILURES = (FloatingPointError, RuntimeError, Warning)


def plan(n: int, seed0: int, family: str) -> list[tuple]:
    """``n`` trials ``(kind, seed)`` from seed ``seed0``: rounds of two effect-free ones,
    every library effect, two pairs and every out-of-library effect ``family`` can
    express, each round interleaved (effect-free, a single, a pair, an out-of-library
    one, a single, ...).

    Examples
    --------
    >>> plan(5, 100, "ross")[:4]
    [(None, 100), ('rub', 101), (('crack', 'runout'), 102), ('line-frequency', 103)]
    """
    skip = UNSUPPORTED[family]
    lib = [k for k in LIB if k not in skip]
    out_ = [k for k in OUT if k not in skip]
    pairs = [p for p in PAIRS if not set(p) & skip]
    kinds, r = [], 0
    while len(kinds) < n:
        two = [pairs[(2 * r) % len(pairs)], pairs[(2 * r + 1) % len(pairs)]]
        queues = [[None, None], list(lib), two, list(out_)]
        while any(queues):
            for q in queues:
                if q:
                    kinds.append(q.pop(0))
        r += 1
    return [(k, seed0 + i) for i, k in enumerate(kinds[:n])]


def member_gaps(measured, truth, family, held) -> dict:
    """Each member of a pair: the held-out excess per feature of the measurement against
    the same plant with that member alone taken out (no noise). A member below the
    visibility bar beside its partner cannot be named by any diagnosis; a member whose
    plant run fails gets None (counted visible)."""
    no_noise = dict(truth, snr_db=400.0)
    out = {}
    for member in truth["effects"]:
        others = {n: p for n, p in truth["effects"].items() if n != member}
        physical = {n: p for n, p in others.items() if n not in MEASUREMENT}
        try:
            clean = simulate(family, truth, physical)
        except PLANT_FAILURES:
            out[member] = None
            continue
        E, n = feature_gap(measured, measure(clean, dict(no_noise, effects=others)), held,
                           others)
        out[member] = E / max(n, 1)
    return out


def _ranking(doc) -> list:
    keep = ("model_error", "replaces", "linear_form_tests", "discrete_settings",
            "rotor_reading", "setting_decided")
    return [{"effect": r["effect"], "shrink": r["shrink"], "log_shrink": r["log_shrink"],
             "E": r["heldout_gap_after"], "score": r["score"], "params": r["params"],
             **{k: r[k] for k in keep if k in r}} for r in doc["ranking"]]


def run_trial(kind, seed: int, family: str, diagnose_kw=None) -> dict:
    """One trial simulated on ``family``'s plant in two passes, diagnosed with both, as
    a record: the truth, the gap before any candidate and its noise floor, the oracle's
    and the effect's own held-out excess, every ranked candidate, the passes' test and
    the verdict; ``{"skipped": reason}`` where the plant diverged."""
    from sknarx.gap import diagnose
    from sknarx.gap.evidence import alternating_split

    t0 = time.perf_counter()
    try:
        measured, truth, oracle, free, down = make_family_trial(kind, seed, family,
                                                                second_pass=True)
    except PLANT_FAILURES as exc:
        return {"kind": kind, "seed": seed, "family": family, "skipped": str(exc)}
    t_plant = time.perf_counter() - t0
    t0 = time.perf_counter()
    d = diagnose(measured, second_pass=down, **(diagnose_kw or {}))
    elapsed = time.perf_counter() - t0
    speeds = np.asarray(SPEEDS)
    held = speeds[~alternating_split(speeds.size)]
    E0 = d["gap_before"]["heldout_excess"]
    e_or, _ = feature_gap(measured, oracle, held, truth["effects"])
    e_eff, n_eff = feature_gap(measured, free, held) if truth["effects"] else (0.0, 1)
    floor = d["gap_before"]["floor"]
    kinds = d.tables["before"].groupby("feature").agg(
        excess=("excess", "mean"), z2=("z2", "mean"), n=("excess", "size"))
    rec = {
        "family": family, "kind": truth["kind"], "seed": seed,
        "in_library": truth["in_library"], "truth": truth,
        "e0": d["gap_before"]["per_feature"], "E0": E0, "n_features": d["n_heldout_features"],
        "floor": {"floor": floor["floor_per_feature"], "median": floor["noise_per_feature"],
                  "n_draws": floor["n_draws"], "false_alarm": floor["false_alarm"]},
        "e0_by_kind": {k: {"excess": float(r.excess), "z2": float(r.z2), "n": int(r.n)}
                       for k, r in kinds.iterrows()},
        "oracle_E": e_or, "oracle_shrink": 1 - e_or / E0 if E0 > 0 else 0.0,
        "effect_gap": e_eff / max(n_eff, 1), "ranking": _ranking(d),
        "passes": {k: d["passes"][k] for k in ("statistic", "z2_ratio", "changed")},
        "verdict": d["verdict"], "seconds": elapsed, "plant_seconds": t_plant,
    }
    if isinstance(rec["kind"], list):
        rec["member_gap"] = member_gaps(measured, truth, family, held)
    return rec
