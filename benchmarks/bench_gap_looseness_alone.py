"""The second plant's loose joints, the looseness alone fitted on the rotor as given and
in the reading ``tilt_share_O = 1``: how many the candidate's form reaches in each.

Run: ``python benchmarks/bench_gap_looseness_alone.py [--seeds 51026,...] [--shard K/N]``
(about 17 s a diagnosis, two a seed; writes
``benchmarks/results/bench_gap_looseness_alone.json``; each diagnosis is appended to
``results/gap_looseness_alone.jsonl`` first, keyed by the diagnosis code's hash, so a
stopped run resumes and two shards on two cores share the log; ``--report-only`` writes
the report from it).

Each seed is a visible second-plant looseness of the package rule's blind runs
(51000-59000; the default list). It is diagnosed with ``candidates=("looseness",)``
and ``exhaustive=True`` (the package's defaults otherwise), once on the nominal rotor as
given and once with ``base = RotorParameters(tilt_share_O=1)``: ``c_O1``, ``c_O2`` on the
disks' tilt, the second plant's reading of where they act, the reading the nominal update
then starts from and is centred at. The verdict is the package rule's on that ranking
(the looseness, or ``unexplained``). It separates the candidate's form from the search
over the library: where the looseness alone is not named in the reading, a deeper
search of readings (``reading_contenders``) cannot name it either; where it is, the
full library in the reading decides whether another effect scores better. Analysis of
a model-form miss (``docs/gap_validation.md``, *The looseness alone in the second
plant's reading*), not a blind evaluation; no threshold is set from it.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, append_log, read_log, table, write_json  # noqa: E402
from bench_gap_blind import code_hash  # noqa: E402
from plants.families import make_family_trial  # noqa: E402

from sknarx.gap import diagnose  # noqa: E402
from sknarx.rotor import RotorParameters  # noqa: E402

#: the visible second-plant loose joints of the runs 51000-59000 (misses_gap_blind.py)
SEEDS = (51026, 51042, 51058, 53010, 53026, 53042, 55010, 55058, 57010, 57042, 59010,
         59026, 59042, 59058)
READINGS = {"as given": None, "tilt_share_O = 1": {"tilt_share_O": 1.0}}
LOG = RESULTS / "gap_looseness_alone.jsonl"


def alone(seed, reading):
    """The looseness alone fitted on second-plant trial ``seed`` in ``reading``."""
    measured, truth, _, _ = make_family_trial("looseness", seed, "second")
    change = READINGS[reading]
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(measured, base=RotorParameters(**change) if change else None,
                     candidates=("looseness",), exhaustive=True)
    fit = next(r for r in d["ranking"] if r["effect"] == "looseness")
    return {"seed": seed, "reading": reading, "verdict": d["verdict"],
            "shrink": fit["shrink"], "log_shrink": fit["log_shrink"],
            "params": fit["params"], "truth": truth["effects"]["looseness"],
            "seconds": time.perf_counter() - t}


def logged(code):
    return {(r["seed"], r["reading"]): r for r in read_log(LOG) if r.get("code") == code}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default=",".join(map(str, SEEDS)),
                    help="second-plant looseness seeds, comma-separated")
    ap.add_argument("--shard", default="0/1", help="K/N: every N-th diagnosis from the K-th")
    ap.add_argument("--report-only", action="store_true",
                    help="write the report from the log, diagnosing nothing")
    args = ap.parse_args(argv)
    try:
        seeds = [int(s) for s in args.seeds.split(",") if s]
        k, n = (int(v) for v in args.shard.split("/"))
    except ValueError:
        ap.error("--seeds takes integers, comma-separated; --shard takes K/N")
    code = code_hash()
    done = logged(code)
    todo = [(s, r) for s in seeds for r in READINGS]
    if not args.report_only:
        for i, key in enumerate(todo):
            if i % n != k or key in done:
                continue
            rec = {**alone(*key), "code": code}
            append_log(LOG, rec)
            done[key] = rec
            print(f"  {key[0]} {key[1]:18s} {rec['verdict']:12s} shrink "
                  f"{rec['shrink']:6.2f}, log shrink {rec['log_shrink']:6.2f} "
                  f"({rec['seconds']:.0f} s)", flush=True)
        if n > 1:
            print("shard done; run with --report-only to write the report")
            return
    rows, named = [], {r: 0 for r in READINGS}
    for s in seeds:
        recs = [done.get((s, r)) for r in READINGS]
        if any(r is None for r in recs):
            continue
        truth = recs[0]["truth"]
        for r in recs:
            named[r["reading"]] += r["verdict"] == "looseness"
        rows.append([s, f"{truth['residual']:.4f}, {1e6 * truth['gap']:.2f} um",
                     *(f"{r['verdict']} ({r['shrink']:.2f} / {r['log_shrink']:.2f})"
                       for r in recs)])
    table(rows, ["seed", "truth: residual, gap",
                 *(f"{r}: verdict (shrink / log shrink)" for r in READINGS)])
    print("named: " + ", ".join(f"{r} {v}/{len(rows)}" for r, v in named.items()))
    write_json("bench_gap_looseness_alone", {
        "command": "python benchmarks/bench_gap_looseness_alone.py " + " ".join(
            argv if argv is not None else sys.argv[1:]),
        "code": code, "named": named, "n_seeds": len(rows),
        "trials": [done[(s, r)] for s in seeds for r in READINGS if (s, r) in done]})


if __name__ == "__main__":
    main()
