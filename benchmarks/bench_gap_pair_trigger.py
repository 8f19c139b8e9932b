"""Would a lower pair trigger name the pairs the update hides, and at what cost on singles?

Run: ``python benchmarks/bench_gap_pair_trigger.py [--family ross] [--pair
anisotropy,runout] [--lead runout] [--shard 0/2]`` (resumable: every finished trial is
appended to its shard's ``results/gap_pair_trigger.shard<i>of<n>.jsonl``; once all
are logged, any process writes ``results/gap_pair_trigger_<pair>.json``).
``misses_gap_blind.py`` found that on ROSS the pairs whose second member the nominal
update followed (a mild anisotropy beside a runout) are missed because the runout alone
leaves as little as it does on runout-only trials, under the pair trigger, so no
partner is tried. This diagnoses again, with the package's code and a pair trigger of
0 (a partner is tried on every trial), each of those missed pairs and every visible
runout-only trial of the package rule's runs (``frontier_gap_blind.RUNS``), and decides
each at a ladder of triggers with the package's other thresholds: how many of the pairs
would be named, and how many runout-only trials would gain a partner they do not have.
It is analysis on trials the rule has already been scored on (the optimistic side),
never a blind score.

``--fresh SEED:N`` scores the same ladder on fresh seeds instead: N pair trials of the
family from seed SEED on (every library pair the family can express, in turn), each
diagnosed with partners tried everywhere and each member's visibility beside the other
measured (:func:`bench_gap_blind.member_gaps`), decided with the thresholds and noise
floor of a finished blind run (``--rule``, by default the latest). Only the pair
trials the blind benchmark would score (detectable, both members visible) are counted.
That is the blind score of the pair rate at each trigger, on draws no trigger was chosen
on; the singles' verdicts do not depend on the search trigger (a pair is named only
above the package's ``pair_trigger``), so it needs no singles. Logs:
``results/gap_pair_trigger_fresh.shard<i>of<n>.jsonl``; report:
``results/gap_pair_trigger_fresh_<family>_<SEED>.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import replace
from pathlib import Path

from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, append_log, table, write_json  # noqa: E402
from bench_gap_blind import (  # noqa: E402
    code_hash,
    detectable,
    member_gaps,
    run_trial,
    search_settings,
    truth_label,
    verdict,
)
from frontier_gap_blind import decided_runs  # noqa: E402
from misses_gap_blind import misses, top2_searched_from  # noqa: E402
from plants.families import PAIRS, UNSUPPORTED  # noqa: E402
from rescore_gap_blind import frozen_thresholds, wilson  # noqa: E402

#: one log per shard process (``gap_pair_trigger.shard<i>of<n>.jsonl``), read together
LOGS = "gap_pair_trigger.shard*.jsonl"
FRESH_LOGS = "gap_pair_trigger_fresh.shard*.jsonl"
#: the finished blind run whose thresholds and noise floor decide the fresh trials
LATEST_RUN = "results/bench_gap_blind_61000_c8e46b2.json"
TRIGGERS = (0.5, 0.2, 0.1, 0.06, 0.03, 0.0)


def trials(family, pair, lead, singles=True, decided=None):
    """The missed ``pair`` trials whose member the update followed, and (with
    ``singles``) the visible ``lead``-only trials, of ``family`` on the package rule's
    runs (``decided``, from :func:`frontier_gap_blind.decided_runs`; loaded if not
    given): ``(kind, seed, the rule that decided it)``."""
    decided = decided_runs() if decided is None else decided
    label = " + ".join(sorted(pair))
    seeds = set(misses(decided)[family]["pairs"][label]["followed_seeds"])
    out = []
    for rule, evals in decided:
        for rec in evals[family]:
            if rec["seed"] in seeds and sorted(rec["kind"]) == sorted(pair):
                # as the blind run drew it: the plan's own tuple
                out.append((next(p for p in PAIRS if sorted(p) == sorted(pair)),
                            rec["seed"], rule))
            elif singles and rec["kind"] == lead and truth_label(rec, rule) == lead \
                    and rec["effect_gap"] > rule.no_gap_per_feature:
                out.append((lead, rec["seed"], rule))
    return out


def fresh_trials(family, seed0, n):
    """``n`` fresh pair trials of ``family`` from ``seed0`` on: ``(kind, seed)``, every
    library pair the family can express in turn."""
    pairs = [p for p in PAIRS if not set(p) & UNSUPPORTED[family]]
    return [(pairs[k % len(pairs)], seed0 + k) for k in range(n)]


def scored_pairs(recs, rule):
    """The fresh trials the blind benchmark scores as pairs under ``rule``: run (not
    skipped by the plant), detectable, and both members visible beside each other."""
    return [r for r in recs if "ranking" in r and detectable(r, rule)
            and isinstance(truth_label(r, rule), list)]


def logged_trials(logs=LOGS):
    """Every logged trial of every shard, by (family, kind, seed, code hash)."""
    out = {}
    for log in sorted(RESULTS.glob(logs)):
        for line in log.read_text().splitlines():
            rec = json.loads(line)
            out[(rec["family"], json.dumps(rec["kind"]), rec["seed"], rec["code"])] = rec
    return out


def run_logged(todo, family, settings, code, log, done, with_member_gaps=False):
    """Diagnose each ``(kind, seed)`` of ``todo`` not yet in ``done`` (from
    :func:`logged_trials`) and append it to ``log``; with ``with_member_gaps``, each
    pair member's visibility beside the other too (:func:`bench_gap_blind.member_gaps`)."""
    for kind, seed in tqdm(todo, desc="trials", unit="trial", file=sys.stderr):
        if (family, json.dumps(kind), seed, code) in done:
            continue
        rec = {**run_trial(kind, seed, family, settings), "code": code}
        if with_member_gaps and "ranking" in rec:
            rec["member_gap"] = member_gaps(kind, seed, family)
        append_log(log, rec)
        print(f"  {family} seed {seed} {kind if isinstance(kind, str) else ' + '.join(kind)}: "
              f"{'skipped' if 'skipped' in rec else 'done'}", flush=True)


def ladder(recs, triggers=TRIGGERS):
    """``recs``, ``(logged trial, its rule)`` pairs, decided at each pair trigger of
    ``triggers`` with the rule's other thresholds: per trigger, how many pair trials are
    named as their pair, how many have both members in the top two of their ranking cut
    back to a search from that trigger, and how many single trials are named right or
    given a partner beside their effect. Only triggers at or above the search's own are
    meaningful (a pair not searched cannot be named)."""
    out = []
    for t in triggers:
        got = {"pair_trigger": t, "pairs named": 0, "pairs in top two": 0, "pairs": 0,
               "singles right": 0, "singles": 0, "singles given a partner": 0}
        for rec, rule in recs:
            v = verdict(rec, replace(rule, pair_trigger=t))[0]
            if isinstance(rec["kind"], list):
                got["pairs"] += 1
                got["pairs named"] += v == sorted(rec["kind"])
                got["pairs in top two"] += set(rec["kind"]) <= top2_searched_from(rec, t)
            else:
                got["singles"] += 1
                got["singles right"] += v == rec["kind"]
                got["singles given a partner"] += isinstance(v, list) and rec["kind"] in v
        out.append(got)
    return out


def run_fresh(args, ap, argv):
    """``--fresh``: the ladder on fresh pair trials (module docstring)."""
    try:
        seed0, n_trials = (int(v) for v in args.fresh.split(":"))
    except ValueError:
        ap.error(f"--fresh takes SEED:N, e.g. 63000:36, not {args.fresh!r}")
    rule = frozen_thresholds(args.rule, ap)
    i, n = (int(v) for v in args.shard.split("/"))
    todo = fresh_trials(args.family, seed0, n_trials)
    code = code_hash()
    settings = replace(search_settings(), pair_trigger=0.0)
    done = logged_trials(FRESH_LOGS)
    log = RESULTS / f"gap_pair_trigger_fresh.shard{i}of{n}.jsonl"
    mine = [t for k, t in enumerate(todo) if k % n == i]
    run_logged(mine, args.family, settings, code, log, done, with_member_gaps=True)
    done = logged_trials(FRESH_LOGS)
    recs = [done.get((args.family, json.dumps(k), s, code)) for k, s in todo]
    if any(r is None for r in recs):
        print(f"{sum(r is None for r in recs)} of {len(recs)} trials still to run",
              file=sys.stderr)
        return
    scored = scored_pairs(recs, rule)
    out = ladder([(r, rule) for r in scored])
    for o in out:
        o["pairs_in_top_two_wilson95"] = wilson(o["pairs in top two"], o["pairs"])
    rows = [[o["pair_trigger"], f"{o['pairs in top two']}/{o['pairs']}",
             "{:.2f}-{:.2f}".format(*o["pairs_in_top_two_wilson95"]),
             f"{o['pairs named']}/{o['pairs']}"] for o in out]
    by_pair = {}
    for r in scored:
        got = by_pair.setdefault(" + ".join(sorted(r["kind"])), {})
        for t in TRIGGERS:
            k, m = got.get(t, (0, 0))
            got[t] = (k + (set(r["kind"]) <= top2_searched_from(r, t)), m + 1)
    print(f"{args.family}: fresh pair trials {seed0}-{seed0 + n_trials - 1}, searched with "
          f"partners everywhere (code {code}), decided by {args.rule}")
    print(f"  {sum('skipped' in r for r in recs)} skipped by the plant, "
          f"{len(scored)} scored (detectable, both members visible)")
    table(rows, ["pair trigger", "pairs in the top two", "Wilson 95 %", "pairs named"])
    table([[p, *(f"{k}/{m}" for k, m in (got[t] for t in TRIGGERS))]
           for p, got in sorted(by_pair.items())],
          ["pair", *(f"top two from {t}" for t in TRIGGERS)])
    write_json(f"gap_pair_trigger_fresh_{args.family}_{seed0}", {
        "command": "python benchmarks/bench_gap_pair_trigger.py " + " ".join(argv or sys.argv[1:]),
        "family": args.family, "code": code, "rule": args.rule,
        "noise_floor_per_feature": rule.no_gap_per_feature,
        "trials": [[k, s] for k, s in todo],
        "skipped": [r["seed"] for r in recs if "skipped" in r],
        "scored": [r["seed"] for r in scored],
        "by_trigger": out,
        "by_pair": {p: {str(t): list(v) for t, v in got.items()}
                    for p, got in by_pair.items()},
        # the diagnosis with partners everywhere, the dearest search
        "median_seconds_trigger_0": statistics.median(
            [r["seconds"] for r in recs if "seconds" in r] or [float("nan")])})


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="ross")
    ap.add_argument("--pair", default="anisotropy,runout")
    ap.add_argument("--lead", default="runout")
    ap.add_argument("--shard", default="0/1", help="this process's share, i/n")
    ap.add_argument("--no-singles", action="store_true",
                    help="the pair trials only: whether they reach the top two, not what "
                         "the search costs the lead's own trials")
    ap.add_argument("--fresh", metavar="SEED:N",
                    help="fresh pair trials instead of the runs' missed ones")
    ap.add_argument("--rule", default=LATEST_RUN,
                    help="the blind run report whose thresholds decide --fresh trials")
    args = ap.parse_args(argv)
    if args.fresh:
        return run_fresh(args, ap, argv)
    pair = args.pair.split(",")
    i, n = (int(v) for v in args.shard.split("/"))
    todo = trials(args.family, pair, args.lead, singles=not args.no_singles)
    code = code_hash()
    settings = replace(search_settings(), pair_trigger=0.0)
    done = logged_trials()
    log = RESULTS / f"gap_pair_trigger.shard{i}of{n}.jsonl"
    mine = [t for k, t in enumerate(todo) if k % n == i]
    run_logged([(k, s) for k, s, _ in mine], args.family, settings, code, log, done)
    done = logged_trials()
    recs = [(done.get((args.family, json.dumps(k), s, code)), rule) for k, s, rule in todo]
    if any(r is None for r, _ in recs):
        print(f"{sum(r is None for r, _ in recs)} of {len(recs)} trials still to run",
              file=sys.stderr)
        return
    out = ladder(recs)
    rows = [[o["pair_trigger"], f"{o['pairs named']}/{o['pairs']}",
             f"{o['pairs in top two']}/{o['pairs']}",
             f"{o['singles right']}/{o['singles']}", o["singles given a partner"]]
            for o in out]
    print(f"{args.family}: the missed {' + '.join(pair)} pairs the update hid, and the "
          f"{args.lead}-only trials, searched with pairs everywhere (code {code})")
    table(rows, ["pair trigger", "pairs named", "pairs in the top two",
                 f"{args.lead} singles right",
                 "singles given a partner"])
    write_json(f"gap_pair_trigger_{'+'.join(sorted(pair))}", {
        "command": "python benchmarks/bench_gap_pair_trigger.py " + " ".join(argv or sys.argv[1:]),
        "family": args.family, "pair": pair, "lead": args.lead, "code": code,
        "trials": [[k, s] for k, s, _ in todo], "by_trigger": out})


if __name__ == "__main__":
    main()
