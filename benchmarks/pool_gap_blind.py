"""The complete blind runs pooled, and how much of each target the data leave in reach.

Run: ``python benchmarks/pool_gap_blind.py`` (``--since 31000``, ``--families
ross,second``; paths relative to ``benchmarks/``). Writes
``results/gap_blind_pooled.json``.

Each run's report (``results/bench_gap_blind_<seeds>_<commit>.json``, as committed: each
run decided by the package's rule of its day, with its own noise floors) gives its
successes and trials; they are summed family by family, with the Wilson 95 % interval of
each pooled rate. Beside the targets' rates it pools the two splits every report makes
(``bench_gap_blind.score``):

* detectable singles the nominal update followed (``separable`` false: after the update
  the sweep is within the effect-free noise floor, so every rule that keeps the
  effect-free sweeps ``no-gap`` says ``no-gap`` here too) and the rest; top-1 on the rest;
  and ``top1_reach``, the top-1 that a diagnosis right on every separable single would
  score;
* likewise detectable pairs one of whose members the update followed, and the rest; both
  members in the top two on the rest; and ``pairs_in_top2_reach``, the rate with every
  separable pair's members in the top two and the others as they were (a followed member
  can still rank second, so they are not all misses as the followed singles are);
* visible out-of-library trials that an in-library fit (or the update alone) matches
  within the noise floor (``within_noise_of_library``), and the rest; ``unexplained`` on
  the rest. On the first kind a rule that judges candidates by their fit can answer
  ``unexplained`` only by refusing a fit it accepts on in-library trials.

Neither split is a score: the targets are scored on every visible trial. They say where
the misses come from, which the caller needs before choosing what to change. The separable
misses are also counted by what the verdict named (truth, verdict), pooled.

This is analysis of finished runs: nothing is decided again (``rescore_gap_blind.py``
does that for one run's logs), and reports written before a split existed (the
beyond-library one from the 37000 run on) are left out of that split's pool, which the
output says.
"""

from __future__ import annotations

import argparse
import collections
import json
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, table, write_json  # noqa: E402
from plants.families import LIB  # noqa: E402
from rescore_gap_blind import wilson  # noqa: E402

#: pooled rate -> (the report's rate, its denominator); a rate whose denominator a
#: report does not carry is left out of that report's pool
RATES = {
    "top1": ("top1", "n_detectable_singles"),
    "top1_separable": ("top1_separable", "n_separable_singles"),
    "pairs_in_top2": ("pairs_in_top2", "n_detectable_pairs"),
    "pairs_in_top2_separable": ("pairs_in_top2_separable", "n_separable_pairs"),
    "false_alarm": ("false_alarm", "n_effect_free"),
    "unexplained_out_of_library": ("unexplained_out_of_library", "n_out_of_library"),
    "unexplained_out_of_library_beyond_library": (
        "unexplained_out_of_library_beyond_library", "n_out_of_library_beyond_library"),
}
REPORT = re.compile(r"bench_gap_blind_(\d+)_([0-9a-f]+)\.json$")


def reports(since, results=RESULTS):
    """``(first seed, commit, report)`` of every committed run from seed ``since`` on,
    in seed order."""
    out = []
    for path in results.glob("bench_gap_blind_*_*.json"):
        m = REPORT.search(path.name)
        if m and int(m.group(1)) >= since:
            out.append((int(m.group(1)), m.group(2), json.loads(path.read_text())))
    return sorted(out, key=lambda r: r[0])


def counts(scores):
    """A report's scores as ``{rate: (successes, trials)}``; a rate the report lacks
    (or whose denominator it lacks) is not there."""
    sc = dict(scores)
    if "n_singles_followed_by_update" in sc:
        sc["n_separable_singles"] = sc["n_detectable_singles"] - sc["n_singles_followed_by_update"]
    if "n_pairs_with_a_member_followed" in sc:
        sc["n_separable_pairs"] = (sc["n_detectable_pairs"]
                                   - sc["n_pairs_with_a_member_followed"])
    out = {}
    for name, (rate, n_key) in RATES.items():
        if n_key not in sc or rate not in sc:
            continue
        n = int(sc[n_key])
        k = int(round(sc[rate] * n)) if n else 0
        out[name] = (k, n)
    if "n_out_of_library_beyond_library" in sc:
        out["out_of_library_within_noise"] = (
            int(sc["n_out_of_library"]) - int(sc["n_out_of_library_beyond_library"]),
            int(sc["n_out_of_library"]))
    return out


def separable_misses(family_report):
    """``(truth, verdict)`` of each separable in-library single the run missed."""
    out = []
    for m in family_report.get("misclassified", []):
        truth, got = m["truth"], m["verdict"]
        if isinstance(truth, str) and truth in LIB and m.get("separable"):
            out.append((truth, got if isinstance(got, str) else " + ".join(got)))
    return out


def _rate(k, n):
    return {"k": k, "n": n, "rate": k / n if n else float("nan"), "interval": list(wilson(k, n))}


def pool(runs, families):
    """Per family: each run's counts, the pooled counts with their intervals, the
    reach of top-1, and the separable misses by (truth, verdict)."""
    out = {}
    for fam in families:
        per_run, total = [], collections.defaultdict(lambda: [0, 0, 0])
        misses = collections.Counter()
        for seed, commit, rep in runs:
            d = rep["families"].get(fam)
            if d is None:
                continue
            c = counts(d["scores"])
            per_run.append({"seeds": seed, "commit": commit, "trials": d["scores"]["n_trials"],
                            **{k: list(v) for k, v in c.items()}})
            if "top1_separable" in c:  # the reach's denominator: runs with the split only
                c["top1_with_split"] = c["top1"]
            if "pairs_in_top2_separable" in c:
                c["pairs_with_split"] = c["pairs_in_top2"]
            for k, (a, b) in c.items():
                total[k][0] += a
                total[k][1] += b
                total[k][2] += 1
            misses.update(separable_misses(d))
        reach = pair_reach = None
        if "top1_separable" in total:
            n_sep, n_all = total["top1_separable"][1], total.pop("top1_with_split")[1]
            reach = _rate(n_sep, n_all)
        if "pairs_in_top2_separable" in total:
            k_sep, n_sep = total["pairs_in_top2_separable"][:2]
            k_all, n_all = total.pop("pairs_with_split")[:2]
            # every separable pair in the top two, the followed ones as they ranked
            pair_reach = _rate(n_sep + (k_all - k_sep), n_all)
        pooled = {k: {"k": a, "n": b, "rate": a / b if b else float("nan"),
                      "interval": list(wilson(a, b)), "runs": r}
                  for k, (a, b, r) in total.items()}
        out[fam] = {"runs": per_run, "pooled": pooled, "top1_reach": reach,
                    "pairs_in_top2_reach": pair_reach,
                    "separable_misses": [{"truth": t, "verdict": v, "n": n}
                                         for (t, v), n in misses.most_common()]}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--since", type=int, default=31000,
                    help="first evaluation seed of the earliest run to pool (default 31000)")
    ap.add_argument("--families", default="ross,second")
    args = ap.parse_args(argv)
    runs = reports(args.since)
    if not runs:
        ap.error(f"no bench_gap_blind_<seeds>_<commit>.json report from seed {args.since} on "
                 f"in {RESULTS}")
    families = args.families.split(",")
    pooled = pool(runs, families)
    print(f"{len(runs)} runs: " + ", ".join(f"{s} ({c})" for s, c, _ in runs))
    rows = []
    for fam, d in pooled.items():
        for name, p in d["pooled"].items():
            rows.append([fam, name, f"{p['k']}/{p['n']}", f"{p['rate']:.3f}",
                         f"{p['interval'][0]:.2f}-{p['interval'][1]:.2f}", p["runs"]])
        for reach, label, split in (
                ("top1_reach", "every separable single right", "top1_separable"),
                ("pairs_in_top2_reach", "every separable pair in the top two",
                 "pairs_in_top2_separable")):
            r = d[reach]
            if r:
                rows.append([fam, f"{reach} ({label})", f"{r['k']}/{r['n']}",
                             f"{r['rate']:.3f}",
                             f"{r['interval'][0]:.2f}-{r['interval'][1]:.2f}",
                             d["pooled"][split]["runs"]])
    table(rows, ["family", "pooled", "k/n", "rate", "95 % interval (Wilson)", "runs"])
    print()
    table([[fam, m["truth"], m["verdict"], m["n"]] for fam, d in pooled.items()
           for m in d["separable_misses"]],
          ["family", "separable single (truth)", "verdict", "trials"])
    write_json("gap_blind_pooled", {
        "command": "python benchmarks/pool_gap_blind.py " + " ".join(argv or sys.argv[1:]),
        "runs": [{"seeds": s, "commit": c} for s, c, _ in runs], "families": pooled})


if __name__ == "__main__":
    main()
