"""A second gate below the no-gap floor, fitted on the own family and tried on fresh
seeds of the independent ones (issue #13; analysis of logged trials, no package change).

Run: ``python benchmarks/bench_gap_subfloor.py --free 12`` (effect-free own-family trials,
logged to ``results/gap_blind_free_own.jsonl`` as they finish, resumable), then
``python benchmarks/bench_gap_subfloor.py --free 12 --evaluate COMMITS --report REPORT``
(``COMMITS`` the blind run's, comma-separated; ``REPORT`` its ``bench_gap_blind`` JSON,
relative to ``benchmarks/``) to fit the gate, apply it to those commits' logged
evaluation trials and write ``results/bench_gap_subfloor.json``.

Below the floor the diagnosis says ``no-gap`` without naming anything: the floor is a
test of the whole held-out gap, and an effect whose signature is a few features (a soft
pedestal under gravity-loaded bearings, on both independent plants) hides in it. The
gate asks a narrower question of the same sweep: does the best single candidate remove
more of that small gap than the best candidate removes on effect-free sweeps? If so,
that candidate is the verdict. Its thresholds are the largest shrink and the largest
log shrink the best single candidate reached on the own family's effect-free trials
(searched exhaustively, as the blind run searches), fixed before any evaluation trial is
read; nothing of the independent families enters them.

The gate needs the search on sweeps below the floor, which the package skips
(``diagnose(..., exhaustive=False)``); the blind run searches every sweep, so its logs
can be decided again under the gate (:mod:`rescore_gap_blind`).
"""

from __future__ import annotations

import argparse
import json
import sys
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402
from bench_gap_blind import run, score, search_settings, truth_label, verdict  # noqa: E402
from rescore_gap_blind import COUNTS, frozen_thresholds, intervals, load  # noqa: E402

#: the own family's effect-free trials for the gate: seeds apart from the null (2000+),
#: pilot (1000+) and evaluation (7000+) seeds
FREE_SEED = 3000


def best_single(rec):
    """The best-scoring single candidate of a logged trial (None without one)."""
    singles = [r for r in rec["ranking"] if isinstance(r["effect"], str)]
    return singles[0] if singles else None


def fit_gate(free):
    """The gate's thresholds: the largest shrink and log shrink of the best single
    candidate over the effect-free trials."""
    best = [b for b in map(best_single, free) if b is not None]
    return {"shrink": max(b["shrink"] for b in best),
            "log_shrink": max(b["log_shrink"] for b in best), "n_free": len(best)}


def gated(rec, s, gate):
    """The trial marked where the gate names its best single candidate: below the floor,
    a best single that passes both thresholds."""
    if rec["e0"] > s.no_gap_per_feature:
        return rec
    b = best_single(rec)
    if b is None or b["shrink"] <= gate["shrink"] or b["log_shrink"] <= gate["log_shrink"]:
        return rec
    return {**rec, "_gate": b}


@contextmanager
def gate_applied():
    """Within: the blind run's scoring (every verdict goes through its ``chosen``) names
    a marked trial's gated candidate, and decides the others as the package does."""
    import bench_gap_blind as blind

    orig = blind.chosen

    def chosen(rec, s, rule=None):
        if rec.get("_gate"):
            return {**rec["_gate"], "heldout_gap_after": rec["_gate"]["E"]}
        return orig(rec, s, rule)

    blind.chosen = chosen
    try:
        yield
    finally:
        blind.chosen = orig


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--free", type=int, default=12, help="effect-free own-family trials")
    ap.add_argument("--evaluate", metavar="COMMITS",
                    help="decide these commits' logged evaluation trials with the gate")
    ap.add_argument("--report", help="the evaluated run's bench_gap_blind JSON (thresholds)")
    ap.add_argument("--families", default="ross,second")
    args = ap.parse_args()
    if args.evaluate and not args.report:
        ap.error("--evaluate needs --report (the evaluated run's frozen thresholds)")
    base = search_settings()  # as the blind run searches
    free = run([(None, FREE_SEED + i) for i in range(args.free)], "free", "own", base)
    if not free:
        ap.error("no effect-free own trials logged")
    gate = fit_gate(free)
    print(f"gate from {gate['n_free']} effect-free own trials: best single shrink > "
          f"{gate['shrink']:.3f} and log shrink > {gate['log_shrink']:.3f}")
    if not args.evaluate:
        return
    frozen = frozen_thresholds(args.report, ap)
    evals = load(args.families.split(","), args.evaluate)
    rows, counted, changed, out = [], [], [], {}
    for fam, recs in evals.items():
        plain = score(recs, frozen)
        decided = [gated(r, frozen, gate) for r in recs]
        with gate_applied():
            with_gate = score(decided, frozen)
            after = [verdict(g, frozen)[0] for g in decided]
        out[fam] = {"package": plain, "gated": with_gate}
        for label, sc in (("package", plain), ("with the gate", with_gate)):
            rows.append([fam, label, len(recs)] + [f"{sc[k]:.2f}" for k in COUNTS])
            counted += [[fam, label, key, f"{k}/{n}", f"{lo:.2f}-{hi:.2f}"]
                        for key, k, n, lo, hi in intervals(sc)]
        for r, b in zip(recs, after, strict=True):
            a = verdict(r, frozen)[0]
            if a != b:
                changed.append([fam, r["seed"], json.dumps(truth_label(r, frozen)),
                                f"{r['e0']:.3f}", json.dumps(a), json.dumps(b)])
    table(rows, ["family", "decision", "trials", *COUNTS])
    print()
    table(counted, ["family", "decision", "rate", "k/n", "95 % interval (Wilson)"])
    print()
    if changed:
        table(changed, ["family", "seed", "truth", "e0", "package", "with the gate"])
    write_json("bench_gap_subfloor", {"gate": gate, "evaluated_commits": args.evaluate,
                                      "report": str(args.report), "families": out,
                                      "changed": changed})


if __name__ == "__main__":
    main()
