"""Where the package's rule misses on its blind runs, effect by effect, and what it can reach.

Run: ``python benchmarks/misses_gap_blind.py`` (about 10 s; writes
``results/gap_blind_misses.json``). It decides every logged trial of the runs that the
package's rule of today decides (``frontier_gap_blind.RUNS``: 51000-59000) by that rule
and sorts the visible in-library trials of each independent plant by their truth:

- a single (or a pair scored as its visible member) is *right*, a miss whose effect
  was still visible after the nominal update (*separable*: a miss of the candidate's
  form, the search or the verdict rule), or a miss the update followed (no candidate
  can name what the updated model already explains to within the noise floor);
- a pair is in the top two of the ranking or not, with the same split.

A plant's *reach* is the rate it would have with every separable miss right and the
others as they are: the target is scored on every visible effect
(``bench_gap_blind.visible``), not only on those the update leaves visible. A target
above the reach needs trials named that the updated model already explains to within
the noise floor, which a better candidate form does not give. Whether a rule could name
them without naming the same effect where it is absent starts from
:func:`alone_leaves` (what one candidate alone leaves, on trials of two truths); a
deeper pair search is tried in ``bench_gap_pair_trigger.py``. This is analysis of
finished runs; it sets nothing.
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402
from bench_gap_blind import (  # noqa: E402
    TARGETS,
    detectable,
    right,
    separable,
    top2_names,
    truth_label,
)
from frontier_gap_blind import FAMILIES, RUNS, decided_runs  # noqa: E402
from rescore_gap_blind import wilson  # noqa: E402

from sknarx.gap.core import effect_names  # noqa: E402


def _label(truth):
    return truth if isinstance(truth, str) else " + ".join(sorted(truth))


def misses(decided):
    """``{family: {"singles": {effect: counts}, "pairs": {pair: counts}}}`` over
    ``decided`` (from :func:`frontier_gap_blind.decided_runs`). Counts: ``trials``,
    ``right`` (for pairs: both in the top two), ``separable`` and ``followed`` (trials
    whose effect the update left visible, and those it followed), their misses
    (``separable_misses``, ``followed_misses``) and the seeds of each miss."""
    out = {fam: {"singles": defaultdict(_counts), "pairs": defaultdict(_counts)}
           for fam in FAMILIES}
    for rule, evals in decided:
        for fam in FAMILIES:
            for rec in evals.get(fam, []):
                if not detectable(rec, rule):
                    continue
                truth = truth_label(rec, rule)
                single = isinstance(truth, str)
                ok = (right(rec, rule) if single
                      else set(rec["kind"]) <= top2_names(rec))
                got = out[fam]["singles" if single else "pairs"][_label(truth)]
                why = "separable" if separable(rec, rule) else "followed"
                got["trials"] += 1
                got[why] += 1
                if ok:
                    got["right"] += 1
                else:
                    got[f"{why}_misses"] += 1
                    got[f"{why}_seeds"].append(rec["seed"])
    return {fam: {kind: dict(sorted(v.items())) for kind, v in got.items()}
            for fam, got in out.items()}


def _counts():
    return {"trials": 0, "right": 0, "separable": 0, "followed": 0,
            "separable_misses": 0, "followed_misses": 0,
            "separable_seeds": [], "followed_seeds": []}


def totals(by_truth):
    """Summed counts of one family's singles or pairs, with the rate, the separable
    rate (right among the trials the update left visible) and the reach (every separable
    miss right), each as ``[k, n]``."""
    n = sum(c["trials"] for c in by_truth.values())
    k = sum(c["right"] for c in by_truth.values())
    n_sep = sum(c["separable"] for c in by_truth.values())
    sep = sum(c["separable_misses"] for c in by_truth.values())
    fol = sum(c["followed_misses"] for c in by_truth.values())
    return {"rate": [k, n], "reach": [n - fol, n], "separable": [n_sep - sep, n_sep],
            "separable_misses": sep, "followed_misses": fol}


def alone_leaves(decided, family, effect, kind):
    """What ``effect``'s single fit leaves (held-out excess per feature) on the visible
    trials of ``family`` whose truth is ``kind`` (an effect, or a pair as a list), by
    seed, from the logged rankings; a trial whose ranking lacks that single is left
    out."""
    out = {}
    for rule, evals in decided:
        for rec in evals.get(family, []):
            if not detectable(rec, rule) or _label(rec["kind"]) != _label(kind):
                continue
            left = single_leaves(rec, effect)
            if left is not None:
                out[rec["seed"]] = left
    return out


def single_leaves(rec, effect):
    """What ``effect`` fitted alone leaves on one logged trial (held-out excess per
    feature, its first single entry in the ranking); None where it was not fitted alone."""
    return next((r["E"] / rec["n_features"] for r in rec["ranking"]
                 if effect_names(r) == (effect,)), None)


def top2_searched_from(rec, trigger):
    """The effects in the top two of a logged trial's ranking cut back to a search that
    tries partners only where the best single leaves more than ``trigger`` per feature
    (its pair entries dropped elsewhere)."""
    singles = [r for r in rec["ranking"] if len(effect_names(r)) <= 1]
    best = min((r["E"] for r in singles), default=0.0) / rec["n_features"]
    ranking = rec["ranking"] if best > trigger else singles
    return {m for r in ranking[:2] for m in effect_names(r)}


def pairs_in_top2_searched_from(decided, family, trigger):
    """``[k, n]``: the visible pair trials of ``family`` whose two members are both in
    the top two of the logged ranking cut back to a search that tries partners only
    where the best single leaves more than ``trigger`` per feature (the pair entries
    dropped elsewhere). At the blind runs' own search trigger it is the scored rate;
    at 0.5 it is what the package's search before ``pair_search_trigger`` ranked (the
    singles as the deeper search left them: a member refitted from a pair can have
    improved its single, so this is close, not exact)."""
    k = n = 0
    for rule, evals in decided:
        for rec in evals.get(family, []):
            if not detectable(rec, rule) or isinstance(truth_label(rec, rule), str):
                continue
            n += 1
            k += set(rec["kind"]) <= top2_searched_from(rec, trigger)
    return [k, n]


def main(argv=None):
    print(f"loading the logs of {len(RUNS)} runs", file=sys.stderr)
    decided = decided_runs()
    got = misses(decided)
    summary = {}
    for fam in FAMILIES:
        for kind, target in (("singles", "top1"), ("pairs", "pairs_in_top2")):
            rows = [[truth, c["trials"], c["right"], c["separable_misses"],
                     c["followed_misses"], " ".join(map(str, c["separable_seeds"]))]
                    for truth, c in got[fam][kind].items()]
            t = totals(got[fam][kind])
            summary.setdefault(fam, {})[kind] = t
            print(f"\n{fam}, {kind} (visible in-library trials, the runs "
                  + ", ".join(run.report.split("_")[-2] for run in RUNS) + ")")
            table(rows, ["truth", "trials", "right" if kind == "singles" else "in top 2",
                         "separable misses", "followed by the update", "separable seeds"])
            (k, n), (r, m) = t["rate"], t["reach"]
            lo, hi = wilson(k, n)
            print(f"  {k}/{n} = {k / n:.3f} ({lo:.2f}-{hi:.2f}); with every separable miss "
                  f"right: {r}/{m} = {r / m:.3f} (target {TARGETS[target]:.2f}); right among "
                  f"those the update left visible: {t['separable'][0]}/{t['separable'][1]}")
    print()
    for fam in FAMILIES:
        (k, n), (k5, _) = (pairs_in_top2_searched_from(decided, fam, t) for t in (0.2, 0.5))
        summary[fam]["pairs_in_top2_searched_from_0.5"] = [k5, n]
        print(f"{fam}: pairs in the top two {k}/{n} as searched (from 0.2 per feature); "
              f"{k5}/{n} with partners tried only where the best single leaves over 0.5")
    followed = []
    print("\nPairs missed with a member the update followed: what the other member alone "
          "leaves there, against what it leaves on its own single trials (per feature)")
    for fam in FAMILIES:
        for pair, c in got[fam]["pairs"].items():
            if not c["followed_seeds"]:
                continue
            # the dominant member: the one whose fit alone leaves least on these misses
            left = {}
            for member in pair.split(" + "):
                on = alone_leaves(decided, fam, member, pair.split(" + "))
                left[member] = [on[s] for s in c["followed_seeds"] if s in on]
            member = min((m for m in left if left[m]), key=lambda m: max(left[m]),
                         default=None)
            alone = sorted(alone_leaves(decided, fam, member, member).values()) if member else []
            if not alone:
                continue
            on_pair = left[member]
            inside = sum(v <= alone[-1] for v in on_pair)
            followed.append({"family": fam, "pair": pair, "member": member,
                             "on_the_pair_misses": on_pair, "on_its_singles": alone})
            print(f"  {fam} {pair}: {member} alone leaves {min(on_pair):.3f}-"
                  f"{max(on_pair):.3f} on the {len(on_pair)} misses, {alone[0]:.3f}-"
                  f"{alone[-1]:.3f} on its {len(alone)} single trials ({inside} of "
                  f"{len(on_pair)} no more than its singles' largest)")
    write_json("gap_blind_misses", {
        "command": "python benchmarks/misses_gap_blind.py",
        "runs": [run.report for run in RUNS], "targets": TARGETS,
        "by_truth": got, "totals": summary, "followed_pair_members": followed})


if __name__ == "__main__":
    main()
