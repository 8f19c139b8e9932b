"""Two passes of one sweep: what a coast-down after the run-up adds to the diagnosis.

Run: ``python benchmarks/bench_gap_passes.py --null 20`` first (the floor), then
``python benchmarks/bench_gap_passes.py --families second,ross [--shard 0/2]`` (two
processes on two cores), then ``--report-only`` to write
``results/bench_gap_passes.json`` (``--report-only --code HASH``: from the logs of a
report's code after the code changed). ``--bow-limit FIRST:LAST`` measures instead how
small a relaxing bow the test still sees (fresh bow draws, each bow scaled). ``--pass-rtol
VALUE`` runs all of it at another relative tolerance than the package's: its own null
pairs first (``--null 20 --pass-rtol VALUE``), whose floor then decides. Every
compared trial is appended to a JSONL log as it finishes
(``results/gap_passes_<phase>_<family>[.shard<k>of<n>].jsonl``): an interrupted run
resumes where it stopped; a logged trial is reused only while the code it depends on (the
pass comparison, the features and the plants) is unchanged.

On one monotone pass a thermal bow relaxing while the speed rises is a smooth 1x change
over speed, which the nominal update follows: most relaxing bows of the blind runs ended
``no-gap`` or as a runout (``docs/gap.md``, *Two passes of one sweep*). Here each trial
of the package rule's runs (``frontier_gap_blind.RUNS``; ``--run REPORT:COMMITS``: of
one finished blind run) gets a second pass from its
own plant (``plants.families.make_family_passes``): the coast-down right after the run-up,
its own noise and keyphasor jitter, and the bow still relaxing. That pass is compared with
the trial's logged measurement, model-free (``sknarx.gap.passes.compare_passes``).

* ``--null``: effect-free pairs of passes of the **own** family (seeds from 2000,
  the null seeds of the blind runs) set the floor of the test's statistic (the shaft
  orders' differences beyond the dead band, squared over their noise and summed, as a
  normal deviate): the larger of a normal's one-sided 1 % point (2.326) and the 99 % point
  of a normal fitted to their statistics. It is frozen in
  ``DiagnosisSettings.pass_floor_sigmas`` before any independent plant is compared.
* The evaluation, on the **independent plants**: each logged trial's verdict is decided
  again as ``diagnose(..., second_pass=...)`` decides it. That is the logged verdict
  unless the passes differ, and then ``unexplained``. Every effect in the library is
  time-invariant, so a sweep whose passes differ is one no candidate explains. Trials
  are compared in the order out-of-library, effect-free, singles, pairs, so a short run
  already answers what the second pass is for. The report gives both verdicts on the
  same trials: top-1 on visible in-library singles, pairs named, false alarms,
  ``unexplained`` on visible out-of-library effects. The ranking, and so "pairs in the
  top two", does not change.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
from _common import PLANT_FAILURES, RESULTS, append_log, read_log, table, write_json  # noqa: E402
from bench_gap_blind import (  # noqa: E402
    detectable,
    hash_files,
    passes_differ,
    score,
    truth_label,
    visible,
)
from plants.families import make_family_passes  # noqa: E402
from rescore_gap_blind import first_pass_only, intervals, wilson  # noqa: E402

from sknarx.gap import DiagnosisSettings  # noqa: E402
from sknarx.gap.passes import compare_passes  # noqa: E402

#: the order trials are compared in: what the second pass is for first
CATEGORIES = ("out-of-library", "effect-free", "single", "pair")
#: the package code a pass comparison depends on (with the plants and the own rotor)
PASS_CODE = ("gap/passes.py", "gap/features.py", "gap/gapmap.py", "gap/measured.py",
             "orders.py")


def code_hash():
    """Hash of the pass comparison's, the features' and the plants' code (comments and
    docstrings aside): a change invalidates the logs."""
    import sknarx

    root = Path(sknarx.__file__).parent
    files = [root / f for f in PASS_CODE] + sorted((root / "rotor").glob("*.py"))
    return hash_files(files + sorted((Path(__file__).parent / "plants").glob("*.py")))


#: a normal's one-sided 1 % point: the floor for records whose noise is what their
#: standard errors say
NORMAL_99 = 2.326


def null_floor(values):
    """The test's floor from effect-free pairs' statistics: the larger of
    :data:`NORMAL_99` and the 99 % point of a normal fitted to them (None with fewer
    than three), rounded to three decimals as frozen."""
    if len(values) < 3:
        return None
    fitted = float(np.mean(values) + NORMAL_99 * np.std(values, ddof=1))
    return round(max(NORMAL_99, fitted), 3)


def compared(kind, seed, family, settings):
    """One trial's two passes compared under ``settings`` (its ``pass_rtol``): the
    test's statistic, the tested orders' z2 over their expectation, each order's mean
    z2 and how long the plant and the comparison took."""
    t = time.perf_counter()
    try:
        first, second, truth = make_family_passes(kind, seed, family)
    except PLANT_FAILURES as exc:  # the plant diverged
        return {"family": family, "seed": seed, "skipped": str(exc)}
    c = compare_passes(first, second, settings=settings)
    doc = c.to_dict()
    return {"family": family, "seed": seed, "kind": truth["kind"],
            "statistic": c.statistic, "z2_ratio": c.z2_ratio,
            "n_tested": doc["n_tested"], "n_features": doc["n_features"],
            "by_order": {k: v["mean_z2"] for k, v in doc["by_order"].items()},
            "largest": doc["largest"][:1], "seconds": time.perf_counter() - t}


def bow_limit(family, seeds, scales, settings):
    """How small a relaxing bow the test still sees: each of ``family``'s thermal-bow
    draws at ``seeds`` with its bow scaled by each of ``scales``, both passes simulated
    (the first as the trial's, the second its coast-down) and compared under
    ``settings``; per scale the bows (m) and the statistics."""
    from plants.families import (
        CHANNELS,
        MEASUREMENT,
        SPEEDS,
        coast_down,
        draw_trial,
        feature_gap,
        measure,
        simulate,
    )

    from sknarx.gap.core import alternating_split

    speeds = np.asarray(SPEEDS)
    held = speeds[~alternating_split(speeds.size)]
    out = {scale: {"bow_m": [], "statistic": [], "effect_gap": []} for scale in scales}
    for seed in seeds:
        truth = draw_trial("thermal-bow", seed, family)
        # the plant without the bow, as the blind benchmark measures an effect's
        # visibility on one pass (bench_gap_blind.visible)
        free = measure(simulate(family, truth, {}),
                       dict(truth, snr_db=400.0, effects={}))
        for scale in scales:
            bow = dict(truth["effects"]["thermal-bow"])
            bow["bow"] *= scale
            t = dict(truth, effects={**truth["effects"], "thermal-bow": bow})
            physical = {n: p for n, p in t["effects"].items() if n not in MEASUREMENT}
            cols = ["speed", "t", *CHANNELS]
            clean = simulate(family, t, physical)
            first = measure(clean, t)[cols]
            second = coast_down(family, t, physical, clean)
            stat = compare_passes(first, second, settings=settings).statistic
            e, n = feature_gap(first, free, held)
            out[scale]["bow_m"].append(bow["bow"])
            out[scale]["statistic"].append(stat)
            out[scale]["effect_gap"].append(e / max(n, 1))
            print(f"  {family} seed {seed} bow x{scale:g} ({1e6 * bow['bow']:.1f} um): "
                  f"{stat:.1f} sigmas, {e / max(n, 1):.2f} per feature on one pass",
                  flush=True)
    return out


def logged(phase, family, code):
    """The logged comparisons of one phase and family under ``code``, by seed."""
    return {r["seed"]: r
            for r in read_log(*sorted(RESULTS.glob(f"gap_passes_{phase}_{family}*.jsonl")))
            if r.get("code") == code}


def run(trials, phase, family, code, shard=(0, 1), settings=None):
    """Compare the ``(kind, seed)`` trials not yet logged (every ``n``-th from the
    ``k``-th with ``shard``) under ``settings``; returns every logged comparison of
    them, by seed."""
    settings = settings or DiagnosisSettings()
    k, n = shard
    log = RESULTS / (f"gap_passes_{phase}_{family}"
                     + (f".shard{k}of{n}" if n > 1 else "") + ".jsonl")
    done = logged(phase, family, code)
    todo = [(i, kind, seed) for i, (kind, seed) in enumerate(trials) if seed not in done]
    for i, kind, seed in todo:
        if i % n != k:
            continue
        r = {**compared(kind, seed, family, settings), "code": code}
        append_log(log, r)
        done[seed] = r
        print(f"  {family} seed {seed} {str(r.get('kind', kind)):28s} "
              + (f"skipped ({r['skipped']})" if "skipped" in r else
                 f"{r['statistic']:9.2f} sigmas, z2 x{r['z2_ratio']:.2f} "
                 f"({r['seconds']:.0f} s)"), flush=True)
    return {s: done[s] for _, s in trials if s in done}


def category(rec, rule):
    """Which of :data:`CATEGORIES` a logged trial is scored in (None: an in-library effect
    under the noise floor, or an out-of-library one, which no verdict can be right on)."""
    if rec["kind"] == "none":
        return "effect-free"
    if not rec["in_library"]:
        return "out-of-library" if visible(rec, rule) else None
    if not detectable(rec, rule):
        return None
    return "single" if isinstance(truth_label(rec, rule), str) else "pair"


def evaluation_trials(family, runs=None):
    """The logged trials of ``family`` as ``(category, record, rule)``, in the order of
    :data:`CATEGORIES`, then by seed: those of ``runs``
    (:class:`frontier_gap_blind.PackageRun`), by default the package rule's."""
    from frontier_gap_blind import RUNS, decided_runs

    out = [(category(rec, rule), rec, rule)
           for rule, evals in decided_runs(runs or RUNS, families=(family,))
           for rec in evals[family]]
    out = [t for t in out if t[0] is not None]
    return sorted(out, key=lambda t: (CATEGORIES.index(t[0]), t[1]["seed"]))


#: the blind benchmark's rates the report pools (bench_gap_blind.score)
RATES = ("top1", "pairs_in_top2", "pairs_verdict", "false_alarm",
         "unexplained_out_of_library", "names_present")


def rates(trials, comparisons, floor):
    """The blind benchmark's rates (:func:`bench_gap_blind.score`, each run decided by its
    own rule) pooled over the runs, on the trials compared: with one pass (the logged
    verdict) and with two (the comparison's statistic as the trial's ``passes``, decided
    at ``floor``), each ``[k, n]``; and per true kind how many trials' passes differed."""
    runs, changed = {}, {}
    for _, rec, rule in trials:
        c = comparisons.get(rec["seed"])
        if c is None or "skipped" in c:
            continue
        rule = replace(rule, pass_floor_sigmas=floor)
        # runs decided by one rule pool into one score (every rate is a count); a run
        # measured in two passes logged its own comparison, which this one replaces
        one, two = runs.setdefault(rule, ([], []))
        one.append(first_pass_only(rec))
        two.append({**one[-1], "passes": {"statistic": c["statistic"]}})
        got = changed.setdefault(json.dumps(rec["kind"]), [0, 0])
        got[0] += passes_differ(two[-1], rule)
        got[1] += 1
    out = {"one_pass": {}, "two_passes": {}}
    for rule, (one, two) in runs.items():
        for key, recs in (("one_pass", one), ("two_passes", two)):
            for name, k, n, *_ in intervals(score(recs, rule)):
                if name in RATES:
                    got = out[key].setdefault(name, [0, 0])
                    got[0] += k
                    got[1] += n
    return out, changed


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--null", type=int, default=0,
                    help="effect-free own-family pairs of passes for the floor (seeds from "
                         "2000)")
    ap.add_argument("--families", default="second,ross",
                    help="independent plants whose logged trials to compare, comma-separated")
    ap.add_argument("--categories", default=",".join(CATEGORIES),
                    help=f"which trials, comma-separated (of {', '.join(CATEGORIES)})")
    ap.add_argument("--shard", default="0/1", help="K/N: every N-th trial from the K-th")
    ap.add_argument("--report-only", action="store_true",
                    help="write the report from the logs, comparing nothing")
    ap.add_argument("--bow-limit", metavar="SEEDS", default=None,
                    help="instead: how small a relaxing bow the test still sees, on "
                         "--families' fresh thermal-bow draws at seeds FIRST:LAST, each "
                         "bow scaled by --bow-scales (writes results/gap_passes_bow_limit"
                         ".json)")
    ap.add_argument("--bow-scales", default="1,0.3,0.1,0.03,0.01",
                    help="with --bow-limit: the scales, comma-separated")
    ap.add_argument("--pass-rtol", type=float, default=None,
                    help="the comparison's relative tolerance (pass_rtol; default the "
                         "package's); another value keys its own logs and is decided at "
                         "the floor its own --null pairs measure")
    ap.add_argument("--run", metavar="REPORT:COMMITS", default=None,
                    help="compare the logged trials of this finished blind run instead of "
                         "the package rule's (its bench_gap_blind report, relative to "
                         "benchmarks/, and the commit prefixes of its logs, comma-"
                         "separated); the report is written as bench_gap_passes_<run>")
    ap.add_argument("--code", default=None,
                    help="with --report-only: the logs of this code hash (a report's "
                         "'code'), written before the code changed; default: the code as "
                         "it is")
    args = ap.parse_args(argv)
    shard = tuple(int(v) for v in args.shard.split("/"))
    runs, run_tag = None, ""
    if args.run:
        from frontier_gap_blind import PackageRun

        report, _, commits = args.run.partition(":")
        if not commits or not (Path(__file__).parent / report).is_file():
            ap.error(f"--run {args.run}: give a blind run's report and its logs' commits, "
                     "e.g. results/bench_gap_blind_61000_c8e46b2.json:3664de5")
        runs = (PackageRun(report, commits),)
        # bench_gap_blind_<first seed>_<commit>.json -> _<first seed>
        run_tag = "_" + Path(report).stem.removeprefix("bench_gap_blind_").split("_")[0]
    if args.code and not args.report_only:
        ap.error("--code reads old logs: it goes with --report-only")
    package = DiagnosisSettings()
    rtol = package.pass_rtol if args.pass_rtol is None else args.pass_rtol
    if not 0.0 <= rtol < 1.0:
        ap.error(f"--pass-rtol {rtol:g}: give a share of a vector's size in [0, 1)")
    settings = replace(package, pass_rtol=rtol)
    # another tolerance is another test: its logs, and its floor, are its own
    tag = "" if rtol == package.pass_rtol else f"+pass_rtol={rtol:g}"
    code = (args.code or code_hash()) + tag
    floor_frozen = package.pass_floor_sigmas
    null = logged("null", "own", code)
    if args.null and not args.report_only and not args.bow_limit:
        print(f"null pairs of passes (own family, effect-free, code {code})", flush=True)
        null = run([(None, 2000 + i) for i in range(args.null)], "null", "own", code, shard,
                   settings)
    null_values = [r["statistic"] for r in null.values() if "skipped" not in r]
    floor_measured = null_floor(null_values)
    if floor_measured is not None:
        print(f"floor from {len(null_values)} null pairs: {floor_measured:.3f} sigmas "
              f"(their mean {np.mean(null_values):.2f}, sd {np.std(null_values, ddof=1):.2f}, "
              f"largest {max(null_values):.2f}); frozen in the package: {floor_frozen:.3f}",
              flush=True)
    if tag:
        if floor_measured is None:
            ap.error(f"--pass-rtol {rtol:g}: no floor measured at this tolerance yet; run "
                     "--null 20 with it first")
        floor_frozen = floor_measured
    if args.bow_limit:
        first, last = (int(v) for v in args.bow_limit.split(":"))
        scales = [float(v) for v in args.bow_scales.split(",")]
        floor = floor_frozen
        no_gap = DiagnosisSettings().no_gap_per_feature
        found, rows = {}, []
        for fam in [f for f in args.families.split(",") if f]:
            got = bow_limit(fam, range(first, last + 1), scales, settings)
            found[fam] = {str(k): v for k, v in got.items()}
            for scale, v in got.items():
                seen = [x > floor for x in v["statistic"]]
                shown = [g > no_gap for g in v["effect_gap"]]
                rows.append([fam, f"x{scale:g}", "{:.1f}-{:.1f} um".format(
                    1e6 * min(v["bow_m"]), 1e6 * max(v["bow_m"])),
                    f"{sum(seen)}/{len(seen)}", f"{min(v['statistic']):.1f}",
                    f"{sum(shown)}/{len(shown)}",
                    f"{sum(a and b for a, b in zip(seen, shown, strict=True))}/{sum(shown)}"])
        table(rows, ["family", "bow scale", "bow at the first step", "passes differ",
                     "weakest (sigmas)", "visible on one pass",
                     "visible ones whose passes differ"])
        write_json("gap_passes_bow_limit" + (f"_rtol{rtol:g}" if tag else ""), {
            "command": "python benchmarks/bench_gap_passes.py " + " ".join(
                argv if argv is not None else sys.argv[1:]),
            "code": code, "pass_rtol": rtol, "floor_sigmas": floor,
            "no_gap_per_feature": no_gap,
            "seeds": [first, last], "families": found})
        return
    cats = [c for c in args.categories.split(",") if c]
    families = [f for f in args.families.split(",") if f]
    if not families:
        # the null pairs alone: the report of the evaluation is left as it is
        return
    results = {}
    for fam in families:
        trials = [t for t in evaluation_trials(fam, runs) if t[0] in cats]
        print(f"{fam}: {len(trials)} logged trials ({', '.join(cats)})", flush=True)
        if args.report_only:
            comps = logged("eval", fam, code)
        else:
            comps = run([(rec["kind"] if rec["kind"] != "none" else None, rec["seed"])
                         for _, rec, _ in trials], "eval", fam, code, shard, settings)
        results[fam] = (trials, comps)
    if shard[1] > 1 and not args.report_only:
        print("shard done; run with --report-only to write the report")
        return
    rows, per_family = [], {}
    for fam, (trials, comps) in results.items():
        pooled, by_kind = rates(trials, comps, floor_frozen)
        per_family[fam] = {**pooled, "changed_by_kind": by_kind,
                           "n_compared": sum(v[1] for v in by_kind.values()),
                           "n_trials": len(trials),
                           "median_seconds": float(np.median(
                               [c["seconds"] for c in comps.values() if "seconds" in c]))
                           if comps else None}
        for name in RATES:
            if name in pooled["two_passes"]:
                # the trials a rate counts can differ (names_present: the named verdicts)
                (k1, n1), (k2, n2) = pooled["one_pass"][name], pooled["two_passes"][name]
                rows.append([fam, name, f"{k1}/{n1}", f"{k2}/{n2}",
                             "{:.2f}-{:.2f}".format(*wilson(k2, n2))])
    if rows:
        table(rows, ["family", "rate", "one pass", "two passes", "two passes, 95 % interval"])
    for fam, d in per_family.items():
        print(f"{fam}: passes differ by true kind: " + ", ".join(
            f"{json.loads(k)} {v[0]}/{v[1]}" for k, v in sorted(d["changed_by_kind"].items())))
    write_json("bench_gap_passes" + run_tag + (f"_rtol{rtol:g}" if tag else ""), {
        "command": "python benchmarks/bench_gap_passes.py " + " ".join(
            argv if argv is not None else sys.argv[1:]),
        "code": code, "pass_rtol": rtol, "floor_frozen": floor_frozen,
        "floor_source": ("measured by this tolerance's null pairs" if tag else
                         "frozen in the package (DiagnosisSettings.pass_floor_sigmas)"),
        "null": {"n": len(null_values), "statistic": null_values,
                 "floor_measured": floor_measured,
                 "median": float(np.median(null_values)) if null_values else None},
        "families": per_family,
        "rule": "a trial's verdict with two passes is its logged verdict unless the passes "
                "differ (the statistic over the frozen floor), then unexplained"})


if __name__ == "__main__":
    main()
