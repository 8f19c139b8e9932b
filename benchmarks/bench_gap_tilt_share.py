"""Logged blind trials diagnosed again with the disks' tilt damping free in the update.

The independent second plant reads the paper's ``c_O1``, ``c_O2`` as damping of the
disks' tilt; sknarx's rotor puts them on the joint, which leaves the disks' tilting
pair at 0.2-0.8 % damping, and a crack's 2x and 3x answer differently on the two
(``bench_crack_station_form.py``). ``RotorParameters.tilt_share_O`` reads a share of
them on the tilts, and the nominal update fits it (prior +-0.5 about 0, bounds 0-1, as
the disk dampers' ``frame_share_d1``, ``frame_share_d2``). The first four trials in the
log were run before the package's update had it, by this script adding the same
parameter at the end of the update's list (see the script as of ``55c392b^``); now the
package fits it and the script runs the package as it is. This re-runs logged
trials of the 25000 and 27000 runs, decided before the update had it, and prints the
verdict, the crack's place and the gap beside the log's.

    python benchmarks/bench_gap_tilt_share.py second:27038 second:27049

Writes ``results/gap_tilt_share.jsonl`` (a trial there is not run again).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_gap_blind as blind  # noqa: E402
import rescore_gap_blind as rescore  # noqa: E402
from _common import logged_eval_trial, rerun_trials  # noqa: E402

LOG = blind.RESULTS / "gap_tilt_share.jsonl"
REPORT = "results/bench_gap_blind_27000_4a216b5.json"


def _summary(rec, s):
    v = blind.verdict(rec, s)[0]
    c = blind.chosen(rec, s)
    place = None
    if isinstance(c, dict):
        params = c["params"] if isinstance(c["params"], list) else [c["params"]]
        place = next((p.get("station") or p.get("at") for p in params
                      if isinstance(p, dict) and (p.get("station") or p.get("at"))), None)
    return {"verdict": v, "place": place, "e0": rec["e0"],
            "best": rec["ranking"][0]["effect"] if rec["ranking"] else None,
            "best_shrink": rec["ranking"][0]["shrink"] if rec["ranking"] else None}


def run(family, seed):
    logged = logged_eval_trial(family, seed, commits=("4a216b5", "f7de2a1"))
    if logged is None:
        raise SystemExit(f"bench_gap_tilt_share: no logged 25000/27000 evaluation trial "
                         f"{family}:{seed}")
    t = time.perf_counter()
    kind = None if logged["kind"] == "none" else logged["kind"]  # effect-free
    rec = blind.run_trial(kind, seed, family, blind.search_settings())
    rec["seconds_total"] = time.perf_counter() - t
    rec["commit"] = blind.git_commit()
    return {"family": family, "seed": seed, "kind": logged["kind"], "logged": logged,
            "tilt": rec}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trials", nargs="+", metavar="FAMILY:SEED")
    args = ap.parse_args(argv)
    s = rescore.frozen_thresholds(REPORT, ap)
    s = replace(s, breadth_waived_at_floor=True)
    for r in rerun_trials(ap, args.trials, blind.FAMILIES, LOG, run):
        family, seed = r["family"], r["seed"]
        share = r["tilt"]["nominal_update"]["changes"].get("tilt_share_O")
        print(f"{family} {seed} {json.dumps(r['kind'])}:")
        print(f"  as logged:       {_summary(r['logged'], s)}")
        print(f"  tilt share free: {_summary(r['tilt'], s)} (tilt_share_O "
              f"{'-' if share is None else f'{share:+.2f}'})")


if __name__ == "__main__":
    main()
