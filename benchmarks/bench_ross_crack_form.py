"""ROSS's crack as written against the same crack with its fixed-frame coupling kept.

ROSS 2.3's Mayes crack (``ross.faults.Crack``) turns the cracked element's stiffness
into the fixed frame and keeps only its diagonal (``plants.ross_paper_rotor._crack_class``):
the coupling between the planes that a crack turning with the shaft has is dropped.
This replays ROSS crack trials of the blind benchmark (``plants.families``, 10 settled
steps, channels ``xO1 yO1 xA yA xB yB``) on the plant as the benchmark draws it
(``crack_form="as-written"``) and with that term kept (``"rotated"``: ROSS's
compliances, element and breathing otherwise unchanged), and diagnoses each with the
crack alone and with the whole library (the package's default settings, exhaustive).
Analysis only: the benchmark's plant is not changed by it and no threshold comes from it.

Run: ``python benchmarks/bench_ross_crack_form.py [--seeds 21008,21022,21036]
[--modes crack,library]`` (writes ``benchmarks/results/bench_ross_crack_form.json``;
each finished row is logged to ``bench_ross_crack_form.jsonl`` beside it with the hash
of the code it ran on, and a re-run resumes from the rows of the same code).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import PLANT_FAILURES, RESULTS, append_log, read_log, table, write_json  # noqa: E402
from bench_gap_blind import code_hash, git_commit  # noqa: E402
from plants.families import feature_gap, make_family_trial  # noqa: E402

from sknarx.gap import diagnose  # noqa: E402

FORMS = ("as-written", "rotated")
MODES = {"crack": ("crack",), "library": None}
LOG = RESULTS / "bench_ross_crack_form.jsonl"


def run(seed, form, mode):
    t = time.perf_counter()
    try:
        measured, truth, oracle, _ = make_family_trial("crack", seed, "ross",
                                                       {"crack_form": form})
    except PLANT_FAILURES as exc:
        return {"seed": seed, "form": form, "mode": mode, "skipped": str(exc)}
    t_plant = time.perf_counter() - t
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        kw = {} if MODES[mode] is None else {"candidates": MODES[mode]}
        d = diagnose(measured, exhaustive=True, **kw)
    E0 = d["gap_before"]["heldout_excess"]
    e_or, _ = feature_gap(measured, oracle, d["split"]["heldout_speeds"])
    crack = next(r for r in d["ranking"] if r["effect"] == "crack")
    return {
        "seed": seed, "form": form, "mode": mode, "truth": truth["effects"]["crack"],
        "verdict": d["verdict"],
        "top": d["ranking"][0]["effect"], "top_shrink": d["ranking"][0]["shrink"],
        "E0": E0, "n_features": d["n_heldout_features"],
        "crack_alone": {"E": crack["heldout_gap_after"], "shrink": crack["shrink"],
                        "log_shrink": crack["log_shrink"], "params": crack["params"]},
        "oracle_E": e_or, "oracle_shrink": 1 - e_or / E0 if E0 > 0 else 0.0,
        "seconds": time.perf_counter() - t, "plant_seconds": t_plant,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="21008,21022,21036",
                    help="ROSS crack trials of the blind benchmark (default: the 21000 "
                         "run's single cracks)")
    ap.add_argument("--modes", default="crack,library", help="of: crack, library")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    modes = args.modes.split(",")
    unknown = set(modes) - set(MODES)
    if unknown:
        ap.error(f"unknown mode(s) {sorted(unknown)}; choose from {sorted(MODES)}")
    code = code_hash()
    done = {(r["seed"], r["form"], r["mode"]): r for r in read_log(LOG)
            if r.get("code") == code}
    for mode in modes:
        for seed in seeds:
            for form in FORMS:
                if (seed, form, mode) in done:
                    continue
                r = {**run(seed, form, mode), "code": code, "commit": git_commit()}
                done[(seed, form, mode)] = r
                append_log(LOG, r)
                print(f"seed {seed} {form:10s} {mode:8s} -> {r.get('verdict', r.get('skipped'))}",
                      flush=True)
    rows, out = [], []
    for mode in modes:
        for seed in seeds:
            for form in FORMS:
                r = done[(seed, form, mode)]
                out.append(r)
                if "skipped" in r:
                    rows.append([seed, form, mode, "skipped (plant)", "", "", "", ""])
                    continue
                c = r["crack_alone"]
                rows.append([seed, form, mode, r["verdict"],
                             f"{r['truth']['depth']:.2f} {r['truth']['station']}",
                             f"{c['params']['depth']:.2f} {c['params']['station']}",
                             f"{c['shrink']:.3f} / {c['log_shrink']:.3f}",
                             f"{r['oracle_shrink']:.3f}"])
    table(rows, ["seed", "crack form", "candidates", "verdict", "true depth, station",
                 "fitted", "crack shrink / log", "oracle shrink"])
    write_json("bench_ross_crack_form", {"rows": out})


if __name__ == "__main__":
    main()
