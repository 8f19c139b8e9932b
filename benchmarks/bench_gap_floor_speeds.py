"""Does the no-gap floor measured on 10-step sweeps hold on 19-step ones?

The package's ``no_gap_per_feature`` (0.34) and per-order floors (``order_floors_z2``)
are quantiles of the held-out gap of effect-free sweeps of our own simulator with 10
speed steps (the blind benchmark's grid, ``plants.families.SPEEDS``). A user's sweep
may have more steps -- issue #13's stepped sweeps have 19. More steps change both sides
of the statistic: the held-out steps lie closer to training ones (the update and the
model-form tolerances interpolate over a shorter span) and the mean runs over more
features (a mean of more terms scatters less). This benchmark measures the gap before
any effect of effect-free sweeps of every family on both grids, the same trial seeds
(so the same plant mismatch and signal-to-noise ratio; the noise and the keyphasor
jitter are drawn afresh), and reports against the frozen floors: the median and
largest gap per feature, how many sweeps are over the floor (a false alarm's
precondition), each order's largest mean z2, and the floor the same recipe would fit on
the own family's sweeps of each grid.

Run: ``python benchmarks/bench_gap_floor_speeds.py [--families own,second,ross]
[--own 20] [--independent 10]`` (each trial appended to
``benchmarks/results/gap_floor_speeds.jsonl`` as it finishes, so a stopped run resumes;
the table and ``benchmarks/results/bench_gap_floor_speeds.json`` at the end). One
process; 40 min of trials on 2026-11-28 sharing this 2-core machine with the test
suite and two blind-benchmark processes.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import PLANT_FAILURES, RESULTS, append_log, read_log, table, write_json  # noqa: E402
from bench_gap_blind import code_hash, lognormal_quantile  # noqa: E402
from bench_gap_cost import SPEEDS_19  # noqa: E402
from plants import families  # noqa: E402

from sknarx.gap import DiagnosisSettings, diagnose  # noqa: E402
from sknarx.gap.core import order_floors  # noqa: E402

GRIDS = {10: families.SPEEDS, 19: SPEEDS_19}  # the blind runs' grid, the cost bench's
#: the blind benchmark's own null seeds, and effect-free seeds of the independent
#: families that no blind run evaluates (its evaluation seeds start at 7000)
OWN_SEED0, INDEPENDENT_SEED0 = 2000, 5000
LOG = RESULTS / "gap_floor_speeds.jsonl"


def gap_before(family, seed, n_steps):
    """The held-out gap of one effect-free sweep before any effect: per feature, and
    each tested order's mean z2 (no candidate is fitted)."""
    families.SPEEDS = GRIDS[n_steps]  # the families read the grid at call time
    t = time.perf_counter()
    measured, *_ = families.make_family_trial(None, seed, family)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(measured, candidates=())
    by_order = d["gap_before"].get("by_order") or {}
    return {"family": family, "seed": seed, "steps": n_steps,
            "e0": d["gap_before"]["per_feature"],
            "n_features": len(d.tables["before"]),
            "z2_by_order": {k: v["mean_z2"] for k, v in by_order.items()},
            "verdict": d["verdict"], "seconds": time.perf_counter() - t}


def _logged(code):
    return {(r["family"], r["seed"], r["steps"]): r for r in read_log(LOG)
            if r.get("code") == code}


def summarise(recs, frozen):
    """Per family and grid (``"own:19"``): sweeps, median held-out features, median and
    largest gap per feature, how many are over ``frozen``'s floor, each tested order's
    largest mean z2, the verdicts, and for the own family (three sweeps or more) the floor
    its recipe -- the 99 % quantile of a log-normal -- would fit there. Skipped trials
    (no ``e0``) are left out."""
    floors = order_floors(frozen)
    groups = {}
    for r in recs:
        if "e0" in r:
            groups.setdefault(f"{r['family']}:{r['steps']}", []).append(r)
    summary = {}
    for key, rs in groups.items():
        e0 = [r["e0"] for r in rs]
        s = {"n": len(rs), "n_features": statistics.median(r["n_features"] for r in rs),
             "median": statistics.median(e0), "max": max(e0),
             "over_floor": sum(x > frozen.no_gap_per_feature for x in e0),
             "verdicts": sorted({r["verdict"] for r in rs}),
             "max_z2_by_order": {k: max(r["z2_by_order"].get(k, 0.0) for r in rs)
                                 for k in floors}}
        if key.startswith("own:") and len(rs) >= 3:
            s["refitted_floor"] = lognormal_quantile(e0, 0.99)
        summary[key] = s
    return summary


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="own,second,ross")
    ap.add_argument("--own", type=int, default=20, help="effect-free own sweeps per grid")
    ap.add_argument("--independent", type=int, default=10,
                    help="effect-free sweeps per grid of each independent family")
    args = ap.parse_args()
    fams = args.families.split(",")
    unknown = [f for f in fams if f not in families.FAMILIES]
    if unknown:
        ap.error(f"--families: unknown {unknown}; choose from {', '.join(families.FAMILIES)}")
    code = code_hash()
    done = _logged(code)
    plan = [(f, (OWN_SEED0 if f == "own" else INDEPENDENT_SEED0) + i, n)
            for f in fams for i in range(args.own if f == "own" else args.independent)
            for n in GRIDS]
    for key in plan:
        if key in done:
            continue
        try:
            rec = gap_before(*key)
        except PLANT_FAILURES as exc:  # the plant diverged
            rec = {"family": key[0], "seed": key[1], "steps": key[2], "skipped": str(exc)}
        rec["code"] = code
        append_log(LOG, rec)
        done[key] = rec
        print(f"  {key[0]} seed {key[1]} {key[2]} steps: "
              + (f"e0 {rec['e0']:.3f} per feature ({rec['seconds']:.0f} s)"
                 if "e0" in rec else f"skipped ({rec['skipped']})"), flush=True)
    frozen = DiagnosisSettings()
    floors = order_floors(frozen)
    summary = summarise([done[k] for k in plan], frozen)
    rows = [[*key.split(":"), s["n"], s["n_features"], f"{s['median']:.3f}",
             f"{s['max']:.3f}", f"{s['over_floor']}/{s['n']}",
             " ".join(f"{k} {v:.2f}" for k, v in s["max_z2_by_order"].items()),
             f"{s['refitted_floor']:.3f}" if "refitted_floor" in s else "-"]
            for key, s in summary.items()]
    print(f"frozen floors: {frozen.no_gap_per_feature} per feature; by order "
          + ", ".join(f"{k} {v}" for k, v in floors.items()) + " (mean z2)")
    table(rows, ["family", "steps", "sweeps", "features", "median e0", "max e0",
                 "over floor", "largest mean z2 by order", "floor refitted (own)"])
    write_json("bench_gap_floor_speeds", {
        "code": code, "frozen": {"no_gap_per_feature": frozen.no_gap_per_feature,
                                 "order_floors_z2": floors},
        "grids": {n: list(g) for n, g in GRIDS.items()}, "summary": summary})


if __name__ == "__main__":
    main()
