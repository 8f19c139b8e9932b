"""What the decision thresholds can trade on the package's rule's blind runs.

Run: ``python benchmarks/frontier_gap_blind.py`` (``--floor``, ``--min-shrink``,
``--min-log-shrink``: comma-separated values of the grid). Writes
``results/gap_blind_frontier.json``.

The verdict of a logged trial is decided from its ranking by three thresholds: the
effect-free floor (``no_gap_per_feature``, below which a sweep is ``no-gap``), and the
held-out shrink and log shrink a named effect needs (``min_shrink``,
``min_log_shrink``). This decides every logged trial of the runs in :data:`RUNS` again
at every point of a grid of the three and pools the rates family by family. The runs
are those decided by the package's rule as it stands: the 51000 run with the
attribution under the floor and the 55000 run without its reading, as in the
analyses of docs/gap_validation.md.

The runs are decided by their reports' thresholds, so with the plain shrink (the
package's until 2026-12-05; ``noise_shrink_gap_blind.py`` decides them with the shrink
above the noise) and on the first pass alone but for the 61000 run, which is not in
:data:`RUNS`. On one pass the out-of-library rate is what lower thresholds cost; with
two passes it no longer moves with them (docs/gap_validation.md, *The noise-referenced
shrink made the package's rule*).

This is analysis of finished runs, and it is optimistic: a point picked from this grid
would be fitted on the trials it scores. So it can show only what no threshold
reaches on these sweeps. It cannot show a setting to adopt, which needs fresh seeds.
Moving the floor also moves which trials count as visible, so each rate's denominator
is printed with it.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table, write_json  # noqa: E402
from bench_gap_blind import TARGETS, score  # noqa: E402
from rescore_gap_blind import (  # noqa: E402
    frozen_thresholds,
    intervals,
    load,
    reported_families,
    without_readings,
)


@dataclass(frozen=True)
class PackageRun:
    """A complete blind run as the package's rule decides it: its report, the commits
    whose logs it is, the decision settings changed from the report's to the package's
    (``what_if``), and whether its trials are decided without their readings."""

    report: str
    commits: str
    what_if: tuple = ()
    without_readings: bool = False


#: the runs the package's rule of today decides: 51000 (the attribution under the floor
#: was off then), 53000, 55000 (run with a reading, decided without it), 57000, 59000
RUNS = (
    PackageRun("results/bench_gap_blind_51000_d2868af.json", "9fe186a,d2868af",
               (("attribute_below_floor", True),)),
    PackageRun("results/bench_gap_blind_53000_3b0682d.json", "1540586,e4378f1"),
    PackageRun("results/bench_gap_blind_55000_ae9aa08.json", "ae9aa08", (), True),
    PackageRun("results/bench_gap_blind_57000_f917659.json", "f917659"),
    PackageRun("results/bench_gap_blind_59000_c1a3131.json", "c1a3131"),
)
FAMILIES = ("ross", "second")
#: the package rule's runs measured in two passes, added to :data:`RUNS` by
#: ``--two-passes``
TWO_PASS_RUNS = (PackageRun("results/bench_gap_blind_61000_c8e46b2.json", "3664de5"),)
#: the code hash of bench_gap_passes.py's comparisons of the 51000-59000 trials (their
#: coast-downs, compared after the runs)
PASSES_CODE = "5aefd9aa0f44e4d5"
#: the pooled rates, each read against its target, with their columns' labels
RATES = {"top1": "top-1", "pairs_in_top2": "pairs", "false_alarm": "false al.",
         "unexplained_out_of_library": "out-of-lib"}
#: the rates these thresholds move (pairs in the top two are the ranking's, not the
#: verdict's)
MOVED = ("top1", "false_alarm", "unexplained_out_of_library")


def decided_runs(runs=RUNS, families=FAMILIES):
    """Each run of ``runs`` as ``(its package rule, its logged trials by family)``, each
    run's trials of the families its report scored."""
    out = []
    for run in runs:
        ap = argparse.ArgumentParser()
        rule = replace(frozen_thresholds(run.report, ap), **dict(run.what_if))
        evals = load(reported_families(run.report, families, ap), run.commits)
        if run.without_readings:
            evals = {fam: [without_readings(r) for r in recs] for fam, recs in evals.items()}
        out.append((rule, evals))
    return out


def with_coast_downs(decided, code=PASSES_CODE):
    """``decided`` (from :func:`frontier_gap_blind.decided_runs`) with each trial that was
    measured in one pass given its compared coast-down (``passes``), where one was logged
    under ``code``; a trial that logged its own comparison keeps it."""
    from bench_gap_passes import logged

    comparisons = {fam: logged("eval", fam, code) for fam in FAMILIES}
    out = []
    for rule, evals in decided:
        out.append((rule, {fam: [
            rec if "passes" in rec or rec["seed"] not in comparisons[fam]
            or "skipped" in comparisons[fam][rec["seed"]]
            else {**rec, "passes": {"statistic": comparisons[fam][rec["seed"]]["statistic"]}}
            for rec in recs] for fam, recs in evals.items()}))
    return out


def pooled(decided, change=None):
    """``{family: {rate: [successes, trials]}}`` summed over ``decided`` (from
    :func:`decided_runs`), each run's rule changed by ``change`` (field -> value)."""
    out = {}
    for rule, evals in decided:
        rule = replace(rule, **(change or {}))
        for fam, recs in evals.items():
            for key, k, n, *_ in intervals(score(recs, rule)):
                got = out.setdefault(fam, {}).setdefault(key, [0, 0])
                got[0] += k
                got[1] += n
    return out


def meets(rate, k, n):
    """Whether ``k`` of ``n`` meets ``rate``'s target (false alarms at most, the others
    at least; no trials meets nothing)."""
    if n == 0:
        return False
    return _rate(k, n) <= TARGETS[rate] if rate == "false_alarm" else _rate(k, n) >= TARGETS[rate]


def frontier(decided, points):
    """One row per point ``(floor, min_shrink, min_log_shrink)`` of ``points``: the
    point, and per family each rate's ``[k, n]``, whether every rate of :data:`RATES`
    meets its target (``meets_all``) and whether the rates the thresholds move do
    (``meets_moved``)."""
    rows = []
    for floor, ms, mls in points:
        point = {"no_gap_per_feature": floor, "min_shrink": ms, "min_log_shrink": mls}
        got = pooled(decided, point)
        rows.append({**point, "families": {
            fam: {**{rate: got[fam][rate] for rate in RATES},
                  "meets_all": all(meets(rate, *got[fam][rate]) for rate in RATES),
                  "meets_moved": all(meets(rate, *got[fam][rate]) for rate in MOVED)}
            for fam in got}})
    return rows


def _rate(k, n):
    return k / n if n else 0.0


def _floats(text):
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a list of numbers; give them comma-separated, e.g. 0.5,0.6"
        ) from None


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--floor", type=_floats, default=(0.34, 0.25, 0.2, 0.15),
                    help="effect-free floors, per feature (default 0.34,0.25,0.2,0.15; "
                         "0.34 is these runs' own)")
    ap.add_argument("--min-shrink", type=_floats, default=(0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
                    help="held-out shrinks a named effect needs (default 0.3,...,0.9)")
    ap.add_argument("--min-log-shrink", type=_floats, default=(0.1, 0.2, 0.3, 0.5),
                    help="held-out log shrinks a named effect needs (default 0.1,0.2,0.3,0.5)")
    ap.add_argument("--two-passes", action="store_true",
                    help="decide with two passes: the runs and the 61000 run (measured "
                         "in two), the others' trials with their coast-downs compared "
                         "after the runs; writes results/gap_blind_frontier_two_passes.json")
    args = ap.parse_args(argv)
    runs = RUNS + (TWO_PASS_RUNS if args.two_passes else ())
    print(f"loading the logs of {len(runs)} runs", file=sys.stderr)
    decided = decided_runs(runs)
    if args.two_passes:
        decided = with_coast_downs(decided)
    grid = list(itertools.product(args.floor, args.min_shrink, args.min_log_shrink))
    rows = frontier(decided, tqdm(grid, desc="grid points", unit="point", file=sys.stderr))

    def cell(fam, row, rate):
        k, n = row["families"][fam][rate]
        return f"{k}/{n}" + ("" if meets(rate, k, n) else " *")

    print("every point decided again on the logs of "
          + ", ".join(run.report.split("_")[-2] for run in runs)
          + (" in two passes" if args.two_passes else "")
          + " (* a rate short of its target)")
    table([[row["no_gap_per_feature"], row["min_shrink"], row["min_log_shrink"],
            *[cell(fam, row, rate) for fam in FAMILIES for rate in RATES]]
           for row in rows],
          ["floor", "min shrink", "min log", *[f"{fam} {label}" for fam in FAMILIES
                                               for label in RATES.values()]])
    print()
    for fam in FAMILIES:
        pairs = sorted({tuple(r["families"][fam]["pairs_in_top2"]) for r in rows})
        n_all = sum(r["families"][fam]["meets_all"] for r in rows)
        n_moved = sum(r["families"][fam]["meets_moved"] for r in rows)
        print(f"{fam}: of {len(rows)} points, {n_all} meet every target and {n_moved} "
              "meet top-1, false alarms and out-of-library together; pairs in the top "
              f"two {' to '.join(f'{k}/{n}' for k, n in pairs)} over the grid.")
        quiet = [r for r in rows if meets("false_alarm", *r["families"][fam]["false_alarm"])]
        if quiet:
            best = max(quiet, key=lambda r: _rate(
                *r["families"][fam]["unexplained_out_of_library"]))
            k, n = best["families"][fam]["unexplained_out_of_library"]
            t, m = best["families"][fam]["top1"]
            print(f"  the most out-of-library `unexplained` within the false-alarm target: "
                  f"{k}/{n} = {_rate(k, n):.2f} (floor {best['no_gap_per_feature']}, min "
                  f"shrink {best['min_shrink']}, min log {best['min_log_shrink']}), where "
                  f"top-1 is {t}/{m} = {_rate(t, m):.2f}")
    write_json("gap_blind_frontier" + ("_two_passes" if args.two_passes else ""), {
        "command": "python benchmarks/frontier_gap_blind.py " + " ".join(argv or sys.argv[1:]),
        "runs": [run.report for run in runs], "two_passes": args.two_passes,
        "targets": TARGETS, "points": rows})


if __name__ == "__main__":
    main()
