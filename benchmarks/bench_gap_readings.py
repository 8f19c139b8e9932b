"""Alternative readings of the nominal rotor as a discrete setting: what they change.

Run: ``python benchmarks/bench_gap_readings.py [--trials second:looseness:51058,...]
[--reading tilt:tilt_share_O=1]`` (writes ``benchmarks/results/bench_gap_readings.json``;
each trial is appended to ``results/bench_gap_readings.jsonl`` first, so a stopped run
resumes). Each trial (``FAMILY:KIND:SEED``, ``KIND`` an effect of the blind benchmark's
draws or ``none`` for an effect-free one, drawn by ``plants.families``) is diagnosed
once by the package's defaults with ``readings`` (``sknarx.gap.readings``): the rotor as
given and the reading of ``--reading``, each fitted and the held-out speeds choosing. The
same run gives the verdict without the reading: the nominal rotor's entries of the same
ranking, decided by the same rule (the verdict's recheck of its discrete settings
aside), and the cost of each part from the diagnosis's own progress ticks, side by
side. The default trials are the second plant's four loose joints of the 51000 run (two
of them missed, ``docs/gap_validation.md``) and effect-free trials of the three
families: what the reading names, and what it raises on sweeps with nothing to name.
It is analysis, not a blind evaluation, and no threshold is set from it.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import PLANT_FAILURES, RESULTS, append_log, read_log, table, write_json  # noqa: E402
from bench_gap_blind import code_hash, parse_readings  # noqa: E402
from plants.families import FAMILIES, make_family_trial  # noqa: E402

from sknarx.gap import DiagnosisSettings, diagnose  # noqa: E402
from sknarx.gap.core import decide, effect_names  # noqa: E402

DEFAULT_TRIALS = ("second:looseness:51026", "second:looseness:51058",
                  "second:looseness:51010", "second:looseness:51042",
                  "second:none:51000", "second:none:51004", "ross:none:51000",
                  "ross:none:51004", "own:none:51000")
LOG = RESULTS / "bench_gap_readings.jsonl"


def verdict_of(choice):
    if choice is None:
        return "unexplained"
    if isinstance(choice, str):
        return choice
    return "no-gap" if not effect_names(choice) else choice["effect"]


def run(family, kind, seed, readings):
    """One trial diagnosed with the readings: both verdicts, what each reading did, and
    the seconds of the nominal rotor's part and of the readings' part."""
    try:
        measured, truth, _, _ = make_family_trial(None if kind == "none" else kind, seed,
                                                  family)
    except PLANT_FAILURES as exc:
        return {"skipped": str(exc)}
    marks = []
    t0 = time.perf_counter()
    settings = DiagnosisSettings()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = diagnose(measured, settings=settings, readings=readings,
                     progress=lambda msg: marks.append((msg, time.perf_counter() - t0)))
    total = time.perf_counter() - t0
    # the readings' part starts at the last tick of the rotor as given
    i = next((i for i, (m, _) in enumerate(marks) if m.startswith("rotor reading")), None)
    first = total if i is None else (marks[i - 1][1] if i else 0.0)
    before = d["gap_before"]
    over = {k for k, v in before["by_order"].items() if v["over_floor"]}
    nominal_only = [r for r in d["ranking"] if "rotor_reading" not in r]
    without = verdict_of(decide(before["per_feature"], nominal_only, settings,
                                d["n_heldout_features"], over))
    top = [{"effect": r["effect"], "reading": r.get("rotor_reading"),
            "shrink": r["shrink"], "log_shrink": r["log_shrink"],
            "E": r["heldout_gap_after"], "params": r["params"]} for r in d["ranking"][:6]]
    return {"truth": kind, "verdict": d["verdict"], "verdict_without_readings": without,
            "rotor_reading": (d.get("rotor_reading") or {}).get("label"),
            "shrink": d["shrink"], "e0": before["per_feature"], "E0": before["heldout_excess"],
            "readings": [{k: r[k] for k in ("label", "heldout_gap_alone", "contenders")}
                         for r in d.get("rotor_readings", [])],
            "top": top, "seconds": total, "seconds_nominal": first,
            "seconds_readings": total - first}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", default=",".join(DEFAULT_TRIALS),
                    help="FAMILY:KIND:SEED items, comma-separated (KIND 'none': "
                         "effect-free)")
    ap.add_argument("--reading", default="tilt:tilt_share_O=1",
                    help="the alternative reading, LABEL:PARAMETER=VALUE[,...] "
                         "(RotorParameters fields), as bench_gap_blind.py takes it")
    args = ap.parse_args()
    readings = parse_readings(ap, [args.reading])
    items = []
    for item in args.trials.split(","):
        family, kind, seed = (item.split(":") + ["", "", ""])[:3]
        if family not in FAMILIES or not seed.isdigit():
            ap.error(f"a trial is FAMILY:KIND:SEED with FAMILY one of {', '.join(FAMILIES)}; "
                     f"got {item!r}")
        items.append((family, kind, int(seed)))
    code = code_hash()
    done = {(r["family"], r["kind"], r["seed"], r["reading"], r["code"]): r
            for r in read_log(LOG)}
    rows = []
    for family, kind, seed in items:
        key = (family, kind, seed, args.reading, code)
        if key not in done:
            print(f"{family}:{kind}:{seed} ...", flush=True)
            rec = {"family": family, "kind": kind, "seed": seed, "reading": args.reading,
                   "code": code, **run(family, kind, seed, readings)}
            append_log(LOG, rec)
            done[key] = rec
        rows.append(done[key])
    table([[r["family"], r["kind"], r["seed"], r.get("verdict_without_readings", "-"),
            r.get("verdict", r.get("skipped", "-")), r.get("rotor_reading") or "-",
            f"{r['shrink']:.2f}" if "shrink" in r else "-",
            f"{r['seconds_nominal']:.0f}" if "seconds" in r else "-",
            f"{r['seconds_readings']:.0f}" if "seconds" in r else "-"] for r in rows],
          ["family", "truth", "seed", "verdict (rotor as given)", "verdict (with reading)",
           "reading of the verdict", "shrink", "s (as given)", "s (reading)"])
    write_json("bench_gap_readings", {"reading": readings, "code": code, "rows": rows})


if __name__ == "__main__":
    main()
