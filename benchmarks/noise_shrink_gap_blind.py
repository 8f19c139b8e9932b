"""The shrink measured above the effect-free noise, on the package rule's blind runs.

Run: ``python benchmarks/noise_shrink_gap_blind.py`` (about a minute; writes
``results/gap_blind_noise_shrink.json``).

A named effect must remove ``min_shrink`` of the held-out gap. Until 2026-12-05 that
share was of the whole gap ``E0``; the package now measures it above the median excess of
effect-free sweeps, ``(E0 - E) / (E0 - n m0)`` (``DiagnosisSettings.noise_per_feature``,
:func:`sknarx.gap.core.judged_shrink`): no candidate removes the noise. The rule was
stated before the 37000 run and scored beside the package's on every run since
(``bench_gap_blind.NoiseReferencedShrink``); its cost on one pass was the relaxing thermal
bows it named, which two passes make ``unexplained`` before any candidate is judged.

This decides the logged trials of the package rule's runs (``frontier_gap_blind.RUNS``,
51000-59000, and the 61000 run) with the plain shrink and with the package's
``noise_per_feature``, each run otherwise by its own rule, on the first pass alone and
with two passes: the 61000 run's own, and for 51000-59000 the coast-downs compared after
the runs (``bench_gap_passes.py``'s logs, under the code hash those comparisons were
made with). It prints the pooled rates per plant and every verdict that changes.

This is analysis of finished runs, and the decision it records was made on them
(docs/gap_validation.md, *The noise-referenced shrink made the package's rule*); the
65000 run is the fresh-seed score.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402
from bench_gap_blind import right, truth_label, verdict  # noqa: E402
from frontier_gap_blind import (  # noqa: E402
    FAMILIES,
    PASSES_CODE,
    RUNS,
    TWO_PASS_RUNS,
    decided_runs,
    pooled,
    with_coast_downs,
)
from rescore_gap_blind import first_pass_only  # noqa: E402

from sknarx.gap import DiagnosisSettings  # noqa: E402

#: the package rule's complete runs: frontier_gap_blind's and the one measured in two passes
PACKAGE_RUNS = RUNS + TWO_PASS_RUNS
#: the rates printed, with their labels
RATES = {"top1": "top-1", "pairs_in_top2": "pairs in top two", "false_alarm": "false alarms",
         "unexplained_out_of_library": "out-of-library", "names_right": "names right"}


def first_passes(decided):
    """``decided`` with every trial's pass comparison left out: the first pass alone."""
    return [(rule, {fam: [first_pass_only(r) for r in recs] for fam, recs in evals.items()})
            for rule, evals in decided]


def changed(decided, change):
    """Every trial whose verdict ``change`` moves (two passes): family, seed, truth, the
    verdict before and after, and whether the new one is right."""
    out = []
    for rule, evals in decided:
        new = replace(rule, **change)
        for fam, recs in evals.items():
            for rec in recs:
                a, b = verdict(rec, rule)[0], verdict(rec, new)[0]
                if a != b:
                    out.append({"family": fam, "seed": rec["seed"],
                                "truth": truth_label(rec, rule), "before": a, "after": b,
                                "right_after": bool(rec["in_library"] and right(rec, new))})
    return sorted(out, key=lambda c: (c["family"], c["seed"]))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.parse_args(argv)
    noise = DiagnosisSettings().noise_per_feature
    print(f"loading the logs of {len(PACKAGE_RUNS)} runs", file=sys.stderr)
    decided = with_coast_downs(decided_runs(PACKAGE_RUNS))
    plain, referenced = {"noise_per_feature": None}, {"noise_per_feature": noise}
    sides = {"two_passes": decided, "one_pass": first_passes(decided)}
    result = {f"{passes}_{name}": pooled(side, change) for passes, side in sides.items()
              for name, change in (("plain", plain), ("referenced", referenced))}

    def cell(fam, key, rate):
        k, n = result[key][fam][rate]
        return f"{k}/{n} = {k / n:.3f}" if n else "-"

    table([[fam, label, *[cell(fam, key, rate) for key in result]]
           for fam in FAMILIES for rate, label in RATES.items()],
          ["plant", "rate", *[k.replace("_", " ") for k in result]])
    moved = changed(decided, referenced)
    print(f"\nverdicts the noise-referenced shrink ({noise} per feature) changes, two passes:")
    table([[c["family"], c["seed"], json.dumps(c["truth"]), json.dumps(c["before"]),
            json.dumps(c["after"]), "right" if c["right_after"] else ""] for c in moved],
          ["plant", "seed", "truth", "plain", "referenced", ""])
    write_json("gap_blind_noise_shrink", {
        "command": "python benchmarks/noise_shrink_gap_blind.py",
        "runs": [run.report for run in PACKAGE_RUNS], "noise_per_feature": noise,
        "passes_code": PASSES_CODE, "rates": result, "changed": moved})


if __name__ == "__main__":
    main()
