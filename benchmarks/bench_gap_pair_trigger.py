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
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

from tqdm.auto import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, append_log, table, write_json  # noqa: E402
from bench_gap_blind import (  # noqa: E402
    code_hash,
    run_trial,
    search_settings,
    truth_label,
    verdict,
)
from frontier_gap_blind import decided_runs  # noqa: E402
from misses_gap_blind import misses, top2_searched_from  # noqa: E402
from plants.families import PAIRS  # noqa: E402

#: one log per shard process (``gap_pair_trigger.shard<i>of<n>.jsonl``), read together
LOGS = "gap_pair_trigger.shard*.jsonl"
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


def logged_trials():
    """Every logged trial of every shard, by (family, kind, seed, code hash)."""
    out = {}
    for log in sorted(RESULTS.glob(LOGS)):
        for line in log.read_text().splitlines():
            rec = json.loads(line)
            out[(rec["family"], json.dumps(rec["kind"]), rec["seed"], rec["code"])] = rec
    return out


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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", default="ross")
    ap.add_argument("--pair", default="anisotropy,runout")
    ap.add_argument("--lead", default="runout")
    ap.add_argument("--shard", default="0/1", help="this process's share, i/n")
    ap.add_argument("--no-singles", action="store_true",
                    help="the pair trials only: whether they reach the top two, not what "
                         "the search costs the lead's own trials")
    args = ap.parse_args(argv)
    pair = args.pair.split(",")
    i, n = (int(v) for v in args.shard.split("/"))
    todo = trials(args.family, pair, args.lead, singles=not args.no_singles)
    code = code_hash()
    settings = replace(search_settings(), pair_trigger=0.0)
    done = logged_trials()
    log = RESULTS / f"gap_pair_trigger.shard{i}of{n}.jsonl"
    mine = [t for k, t in enumerate(todo) if k % n == i]
    for kind, seed, _ in tqdm(mine, desc="trials", unit="trial", file=sys.stderr):
        key = (args.family, json.dumps(kind), seed, code)
        if key in done:
            continue
        rec = {**run_trial(kind, seed, args.family, settings), "code": code}
        append_log(log, rec)
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
