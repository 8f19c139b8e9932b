"""Blind validation of the gap diagnosis on trials whose effect is withheld.

Run: ``python benchmarks/bench_gap_blind.py [--pilot 32] [--trials 100]``
(writes ``benchmarks/results/bench_gap_blind.json`` and per-trial JSONL logs that
let an interrupted run resume). On two cores, ``--shard 0/2`` and ``--shard 1/2`` in
two processes, then one run without ``--shard`` to write the report.

Each trial draws an effect (none, one of the library, a pair, or one outside the
library: a 50 Hz electrical line, a thermal bow), its severity and parameters,
rig-like mismatch of stiffness (+-3 %), damping (+-5 %) and unbalance (+-5 %, any
phase), noise (SNR 20-40 dB) and keyphasor jitter (+-2 deg per step), and simulates
a 10-step sweep (1 s per step at 1 kHz). The diagnosis runs exhaustively (every
candidate, pairs when needed); the verdict thresholds are fitted on PILOT seeds only and then frozen
and applied to fresh EVALUATION seeds. The no-gap threshold is the noise floor: the 99 %
quantile of the held-out excess of NULL (effect-free) trials, which run only the nuisance
calibration.
"""

from __future__ import annotations

import argparse
import itertools
import json
import subprocess
import sys
import time
import warnings
from dataclasses import asdict, replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
from _common import RESULTS, table, write_json  # noqa: E402
from scipy import stats  # noqa: E402

from sknarx.gap import DiagnosisSettings, diagnose  # noqa: E402
from sknarx.gap.diagnosis import decide  # noqa: E402
from sknarx.gap.settings import SEARCH_FIELDS  # noqa: E402
from sknarx.gap.synthetic import make_trial, oracle_gap  # noqa: E402
from sknarx.rotor import EFFECTS  # noqa: E402

LIB = ["rub", "misalignment", "crack", "looseness", "clearance", "anisotropy", "runout",
       "speed-fluctuation"]
PAIRS = [("runout", "crack"), ("anisotropy", "runout"), ("misalignment", "clearance"),
         ("crack", "speed-fluctuation")]
OUT = ["line-frequency", "thermal-bow"]


def git_commit():
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


#: the modules a blind trial runs through (the frozen thresholds in gap/settings.py only
#: read the outcome, and the order-domain and beam-rotor modules are not used)
TRIAL_CODE = ("gap/calibration.py", "gap/diagnosis.py", "gap/features.py", "gap/gapmap.py",
              "gap/measured.py", "gap/synthetic.py", "rotor/bearings.py", "rotor/effects.py",
              "rotor/integrator.py", "rotor/linear.py", "rotor/matrices.py",
              "rotor/parameters.py", "rotor/simulator.py", "rotor/sweep_table.py")


def diagnosis_code_hash():
    """Hash of the code a trial's outcome depends on."""
    import hashlib

    import sknarx

    root = Path(sknarx.__file__).parent
    h = hashlib.sha256()
    for f in TRIAL_CODE:
        h.update((root / f).read_bytes())
    return h.hexdigest()[:16]


def plan(n, seed0):
    """A balanced list of trial kinds: effect-free, singles, pairs, out-of-library.

    Rounds of 16: two effect-free, the eight library effects, two pairs (the four
    pairs of ``PAIRS`` alternate between rounds) and two of each out-of-library effect.
    """
    out = []
    r = 0
    while len(out) < n:
        pairs = [PAIRS[(2 * r) % len(PAIRS)], PAIRS[(2 * r + 1) % len(PAIRS)]]
        out += [None] * 2 + LIB + pairs + OUT * 2
        r += 1
    return [(k, seed0 + i) for i, k in enumerate(out[:n])]


def run_trial(kind, seed, settings, exhaustive=True):
    try:
        measured, truth = make_trial(kind, seed)
    except RuntimeError as exc:  # every draw was physically unstable (e.g. joint resonance)
        return {"kind": kind, "seed": seed, "skipped": str(exc)}
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(measured, settings=settings, exhaustive=exhaustive)
    elapsed = time.perf_counter() - t
    held = d["split"]["heldout_speeds"]
    E0 = d["gap_before"]["heldout_excess"]
    Eor = oracle_gap(measured, truth, held) if truth["in_library"] and truth["effects"] else None
    return {
        "kind": truth["kind"], "seed": seed, "in_library": truth["in_library"],
        "truth": truth, "e0": d["gap_before"]["per_feature"], "E0": E0,
        "oracle_shrink": None if Eor is None else 1 - Eor / E0 if E0 > 0 else 0.0,
        "n_features": d.get("n_heldout_features", 1),
        "ranking": [{"effect": r["effect"], "shrink": r["shrink"], "log_shrink": r["log_shrink"],
                     "E": r["heldout_gap_after"], "score": r["score"], "params": r["params"]}
                    for r in d["ranking"]],
        "seconds": elapsed,
    }


def verdict(rec, s):
    ranking = [{**r, "_names": (r["effect"],) if isinstance(r["effect"], str)
                else tuple(r["effect"]), "_shrink": r["shrink"], "_E": r["E"]}
               for r in rec["ranking"]]
    choice = decide(rec["e0"], ranking, s, rec["n_features"])
    if choice == "no-gap":
        return "no-gap", 0.0
    if choice is None:
        return "unexplained", 0.0
    names = choice["_names"]
    return (names[0] if len(names) == 1 else sorted(names)), choice["_shrink"]


def truth_label(rec):
    k = rec["kind"]
    return "no-gap" if k == "none" else (sorted(k) if isinstance(k, list) else k)


def detectable(rec, s):
    return (rec["in_library"] and rec["kind"] != "none" and rec["e0"] > s.no_gap_per_feature
            and (rec["oracle_shrink"] or 0) >= s.min_shrink)


def score(recs, s):
    lib = [r for r in recs if detectable(r, s)]
    free = [r for r in recs if r["kind"] == "none"]
    out = [r for r in recs if not r["in_library"]]
    # the target counts every out-of-library trial; the rate over those leaving a
    # gap above the noise floor is reported beside it
    out_seen = [r for r in out if r["e0"] > s.no_gap_per_feature]
    top1 = np.mean([verdict(r, s)[0] == truth_label(r) for r in lib]) if lib else np.nan
    fa = np.mean([verdict(r, s)[0] != "no-gap" for r in free]) if free else np.nan
    unexp = np.mean([verdict(r, s)[0] == "unexplained" for r in out]) if out else np.nan
    unexp_seen = (np.mean([verdict(r, s)[0] == "unexplained" for r in out_seen])
                  if out_seen else np.nan)
    ratios = [verdict(r, s)[1] / r["oracle_shrink"] for r in lib
              if verdict(r, s)[0] == truth_label(r) and r["oracle_shrink"] > 0]
    return {"top1": top1, "false_alarm": fa, "unexplained_out_of_library": unexp,
            "unexplained_out_of_library_with_gap": unexp_seen,
            "shrink_vs_oracle_median": float(np.median(ratios)) if ratios else np.nan,
            "n_detectable": len(lib), "n_effect_free": len(free),
            "n_out_of_library": len(out), "n_out_of_library_with_gap": len(out_seen)}


GRID = {"min_shrink": [0.5, 0.6, 0.7, 0.8],
        "min_log_shrink": [0.0, 0.3, 0.5, 0.6, 0.7],
        "pair_trigger": [0.2, 0.5, 1.0, 2.0],
        "pair_gain": [0.3, 0.5, 0.7]}


def noise_floor(null, alpha=0.01):
    """The no-gap threshold: the ``1 - alpha`` quantile of the held-out excess per
    feature of effect-free trials (log-normal fit: the excess is positive and skewed).

    Set from the null distribution, not from a tie of the pilot grid: on 32 pilot trials
    any threshold between the largest effect-free excess and the weakest pilot effect
    ties, and the middle of that tie hid real gaps two to three times the noise floor.
    """
    z = np.log([r["e0"] for r in null])
    return float(np.exp(z.mean() + stats.norm.ppf(1.0 - alpha) * z.std(ddof=1)))


def fit_thresholds(pilot, base):
    """Grid search on pilot trials: maximise the worst of the three rates.

    Many settings tie on a few dozen pilot trials; among the tied ones each threshold
    takes the median of its tied values (away from the edges of the tied region), if
    that combination is itself optimal. ``pair_trigger`` can only be raised above the
    value the trials were run with (below it, no pairs were searched) and not below the
    noise floor.
    """
    def value(s):
        sc = score(pilot, s)
        vals = [sc["top1"], 1 - sc["false_alarm"], sc["unexplained_out_of_library"]]
        return np.nanmin(vals) + 1e-3 * np.nanmean(vals)

    # a single that leaves less than the noise floor has explained the gap: no pair
    # can be needed, so the trigger is not searched below the floor either
    grid = dict(GRID, pair_trigger=[t for t in GRID["pair_trigger"]
                                    if t >= max(base.pair_trigger, base.no_gap_per_feature)])
    names = list(grid)
    scored = [(value(replace(base, **dict(zip(names, combo, strict=True)))), combo)
              for combo in itertools.product(*grid.values())]
    top = max(v for v, _ in scored)
    tied = [c for v, c in scored if v >= top - 1e-12]
    mid = tuple(sorted(col)[(len(col) - 1) // 2] for col in zip(*tied, strict=True))
    pick = mid if mid in tied else tied[0]
    return replace(base, **dict(zip(names, pick, strict=True)))


def run(trials, phase, settings, shard=(0, 1), report_only=False, exhaustive=True):
    """Run (or reload) ``trials`` (kind, seed) of ``phase``; ``shard = (k, n)`` runs every
    n-th only.

    Each process appends to its own log; all logs of the phase are read back.
    """
    commit = git_commit()
    code = diagnosis_code_hash() + str([getattr(settings, f) for f in SEARCH_FIELDS])
    k, n_shards = shard
    suffix = f".shard{k}of{n_shards}" if n_shards > 1 else ""
    log = RESULTS / f"gap_blind_{phase}{suffix}.jsonl"
    done, stale = {}, 0
    for path in sorted(RESULTS.glob(f"gap_blind_{phase}*.jsonl")):
        for line in path.read_text().splitlines():
            r = json.loads(line)
            # a logged trial is reused only if the diagnosis code has not changed since
            if r.get("diagnosis_code") == code:
                done[r["seed"]] = r
            else:
                stale += 1
    if stale:
        print(f"  {stale} logged trials from other code ignored", flush=True)
    recs = []
    for i, (kind, seed) in enumerate(trials):
        if seed in done:
            if "skipped" not in done[seed]:
                recs.append(done[seed])
            continue
        if i % n_shards != k or report_only:
            continue
        r = run_trial(kind, seed, settings, exhaustive)
        r["commit"], r["diagnosis_code"] = commit, code
        with log.open("a") as f:
            f.write(json.dumps(r, default=float) + "\n")
        if "skipped" in r:
            print(f"  seed {seed} {kind}: skipped ({r['skipped']})", flush=True)
            continue
        recs.append(r)
        print(f"  seed {seed} {str(r['kind']):28s} e0 {r['e0']:9.2f} "
              f"best {r['ranking'][0]['effect'] if r['ranking'] else '-'} "
              f"({r['seconds']:.0f} s)", flush=True)
    n_logged = sum(1 for _, seed in trials if seed in done) if report_only else len(trials)
    return recs, n_logged


def confusion(recs, s):
    labels = sorted({json.dumps(truth_label(r)) for r in recs})
    mat = {}
    for r in recs:
        t, v = json.dumps(truth_label(r)), json.dumps(verdict(r, s)[0])
        mat.setdefault(t, {}).setdefault(v, 0)
        mat[t][v] += 1
    return {"labels": labels, "counts": mat}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pilot", type=int, default=32)
    ap.add_argument("--trials", type=int, default=101)
    ap.add_argument("--null", type=int, default=60,
                    help="effect-free trials that set the noise floor (nuisance fit only)")
    ap.add_argument("--eval-seed", type=int, default=7000,
                    help="first evaluation seed (5000-5100 and 6000-6100 were seen while "
                         "designing: their misses led to the nominal start and the re-fits)")
    ap.add_argument("--shard", default="0/1",
                    help="K/N: run every N-th trial from the K-th (parallel processes); "
                         "run once more without it to write the report")
    ap.add_argument("--report-only", action="store_true",
                    help="write the report from the logged trials, running none")
    args = ap.parse_args()
    shard = tuple(int(v) for v in args.shard.split("/"))
    RESULTS.mkdir(exist_ok=True)
    # pairs are searched from a low trigger so the fitted trigger can be any value above
    base = replace(DiagnosisSettings(), pair_trigger=0.2)
    print("null trials (noise floor)")
    null_plan = [(None, 2000 + i) for i in range(args.null)]
    null, n_null = run(null_plan, "null", replace(base, no_gap_per_feature=np.inf), shard,
                       args.report_only, exhaustive=False)
    print("pilot trials (threshold fitting)")
    pilot, n_pilot = run(plan(args.pilot, 1000), "pilot", base, shard, args.report_only)
    print("evaluation trials (fresh seeds)")
    ev, n_eval = run(plan(args.trials, args.eval_seed), "eval", base, shard,
                     args.report_only)
    if shard[1] > 1:
        print("shard done; run without --shard to write the report")
        return
    floor = noise_floor(null)
    frozen = fit_thresholds(pilot, replace(base, no_gap_per_feature=round(floor, 3)))
    print("frozen thresholds:", frozen)
    sc = score(ev, frozen)
    times = [r["seconds"] for r in ev]
    table([[k, f"{v:.3f}" if isinstance(v, float) else v] for k, v in sc.items()] +
          [["median seconds per diagnosis (10 steps)", f"{np.median(times):.0f}"]],
          ["metric", "value"])
    write_json("bench_gap_blind", {
        "thresholds": asdict(frozen), "pilot": score(pilot, frozen), "evaluation": sc,
        "targets": {"top1": 0.9, "false_alarm": 0.05, "unexplained_out_of_library": 0.8,
                    "shrink_vs_oracle_median": 0.9, "n_trials": 100},
        "confusion": confusion(ev, frozen), "n_trials": len(ev),
        "noise_floor": {"no_gap_per_feature": floor, "quantile": 0.99, "n_null": len(null),
                        "null_e0_median": float(np.median([r["e0"] for r in null])),
                        "null_e0_max": float(max(r["e0"] for r in null))},
        "planned": {"null": args.null, "pilot": args.pilot, "evaluation": args.trials},
        "complete": (n_null == args.null and n_pilot == args.pilot
                     and n_eval == args.trials),
        "misclassified": [{"seed": r["seed"], "truth": truth_label(r),
                           "verdict": verdict(r, frozen)[0], "e0": r["e0"]}
                          for r in ev if (detectable(r, frozen) or not r["in_library"]
                                          or r["kind"] == "none")
                          and verdict(r, frozen)[0] != (truth_label(r) if r["in_library"]
                                                        else "unexplained")],
        "median_seconds": float(np.median(times)), "library": sorted(EFFECTS),
    })


if __name__ == "__main__":
    main()
