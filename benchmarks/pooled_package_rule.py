"""The blind runs the package's rule of now decides in two passes, pooled, misses by kind.

Run: ``python benchmarks/pooled_package_rule.py`` (about 10 s; writes
``results/gap_blind_pooled_package_rule.json``).

The runs: ``frontier_gap_blind.RUNS`` (51000-59000, each trial given its logged
coast-down from ``bench_gap_passes.py``), ``TWO_PASS_RUNS`` (61000) and :data:`LATER_RUNS`
(65000 on), each decided by its report's frozen thresholds and floors with the package's
verdict rule of now (``DiagnosisSettings.noise_per_feature``: the share removed above the
effect-free noise). ``pool_gap_blind.py`` pools the reports as each run's rule wrote them
(the plain shrink before 2026-12-05, one pass before 61000); this decides them all by
one rule. Per family: each rate pooled with its Wilson 95 % interval (with, beside the
targets' rates, top-1 and pairs in the top two on the trials whose effects are still
visible after the nominal update), and the misses sorted by kind --

* a detectable single: named with a partner (the right effect and one more), ``no-gap``
  (the nominal update followed it), ``unexplained``, or another effect named;
* a detectable pair: a member the update followed (``bench_gap_blind.separable`` false)
  or one it left visible.

Analysis of finished runs; the rule was chosen before the runs after 61000 and on the
ones before (docs/gap_validation.md), so only those later runs are its fresh-seed score:
``--later-only`` pools them alone (writes ``results/gap_blind_pooled_package_rule_later.json``).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from dataclasses import replace
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
    verdict,
)
from frontier_gap_blind import (  # noqa: E402
    FAMILIES,
    RUNS,
    TWO_PASS_RUNS,
    PackageRun,
    decided_runs,
    pooled,
    with_coast_downs,
)
from rescore_gap_blind import wilson  # noqa: E402

from sknarx.gap import DiagnosisSettings  # noqa: E402

#: runs after the 61000 run, measured in two passes, searched as the package searches
#: now (pairs from 0.1)
LATER_RUNS = (PackageRun("results/bench_gap_blind_65000_ed0d201.json", "ed0d201"),
              PackageRun("results/bench_gap_blind_67000_af72500.json", "af72500"),
              PackageRun("results/bench_gap_blind_69000_0ab344c.json", "0ab344c"))
#: the rates reported, with their labels
RATES = {"top1": "top-1", "pairs_in_top2": "pairs in top two", "false_alarm": "false alarms",
         "unexplained_out_of_library": "out-of-library `unexplained`",
         "names_right": "names right",
         "top1_separable": "top-1, singles visible after the update",
         "pairs_in_top2_separable": "pairs in top two, members visible after the update"}


def single_miss(rec, rule):
    """What a detectable single's wrong verdict is: ``partner`` (its effect and one
    more), ``no-gap``, ``unexplained`` or ``other`` (another effect named)."""
    got = verdict(rec, rule)[0]
    if got in ("no-gap", "unexplained"):
        return got
    return "partner" if isinstance(got, list) and truth_label(rec, rule) in got else "other"


def misses(decided):
    """``{family: {"singles": {kind: [(seed, truth, verdict)]}, "pairs": {"followed" |
    "visible": [(seed, truth, top two)]}}}`` over ``decided``."""
    out = {fam: {"singles": {}, "pairs": {}} for fam in FAMILIES}
    for rule, evals in decided:
        for fam, recs in evals.items():
            for r in recs:
                if not detectable(r, rule):
                    continue
                t = truth_label(r, rule)
                if isinstance(t, str):
                    if not right(r, rule):
                        out[fam]["singles"].setdefault(single_miss(r, rule), []).append(
                            (r["seed"], t, verdict(r, rule)[0]))
                elif not set(r["kind"]) <= top2_names(r):
                    kind = "visible" if separable(r, rule) else "followed"
                    out[fam]["pairs"].setdefault(kind, []).append(
                        (r["seed"], " + ".join(t), sorted(top2_names(r))))
    return out


#: every run the package's rule of now decides in two passes
PACKAGE_RULE_RUNS = RUNS + TWO_PASS_RUNS + LATER_RUNS


def decided_by_package_rule(runs=PACKAGE_RULE_RUNS):
    """``runs`` as ``(rule, logged trials by family)``, each trial with its coast-down
    and each rule the run's frozen thresholds with the package's verdict share."""
    noise = DiagnosisSettings().noise_per_feature
    return [(replace(rule, noise_per_feature=noise), evals)
            for rule, evals in with_coast_downs(decided_runs(runs))]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--later-only", action="store_true",
                    help="pool only the runs after 61000 (LATER_RUNS), the rule's "
                         "fresh-seed score")
    args = ap.parse_args(argv)
    runs = LATER_RUNS if args.later_only else PACKAGE_RULE_RUNS
    print(f"loading the logs of {len(runs)} runs", file=sys.stderr)
    noise = DiagnosisSettings().noise_per_feature
    decided = decided_by_package_rule(runs)
    got = pooled(decided)
    rows = []
    for fam, rates in got.items():
        for rate, label in RATES.items():
            k, n = rates[rate]
            lo, hi = wilson(k, n)
            rows.append([fam, label, f"{k}/{n}", f"{k / n:.3f}" if n else "-",
                         f"{lo:.2f}-{hi:.2f}", TARGETS.get(rate, "-")])
    table(rows, ["family", "rate", "k/n", "rate", "95 % interval (Wilson)", "target"])
    found = misses(decided)
    print()
    table([[fam, what, kind, len(items)] for fam, d in found.items()
           for what in ("singles", "pairs") for kind, items in sorted(d[what].items())],
          ["family", "detectable", "miss", "trials"])
    write_json("gap_blind_pooled_package_rule" + ("_later" if args.later_only else ""), {
        "command": "python benchmarks/pooled_package_rule.py"
                   + (" --later-only" if args.later_only else ""),
        "runs": [run.report for run in runs], "noise_per_feature": noise,
        "families": {fam: {"rates": {rate: {"k": got[fam][rate][0], "n": got[fam][rate][1],
                                            "interval": list(wilson(*got[fam][rate]))}
                                     for rate in RATES},
                           "misses": found[fam],
                           "miss_counts": {what: dict(Counter({k: len(v) for k, v in
                                                              found[fam][what].items()}))
                                           for what in ("singles", "pairs")}}
                     for fam in got}})


if __name__ == "__main__":
    main()
