"""Where a candidate's breadth goes: the log-excess it lowers and the log-excess it raises.

``log_shrink`` (:func:`sknarx.gap.core.log_shrink`) is the share of ``sum(log(1 +
excess))`` a candidate removes. Low, it can mean two things: the candidate *breaks*
features (raises their excess: a clearance rattling broadband to mimic a 50 Hz line) or
it *leaves* features it does not touch (the thin model-form residual of a rotor the
model does not describe exactly). This re-runs logged blind trials with the same search
(so the ranking is the log's) and splits each candidate's log-excess change into the
gain on the features it lowers and the harm on those it raises.

    python benchmarks/bench_gap_breadth.py second:27005 second:27003 ross:27003

Writes ``results/gap_breadth_split.jsonl`` (one line a trial; a trial already there is
not run again) and prints, per trial, the four best candidates: shrink (the run's and
the log's), log shrink, log gain, log harm, the total log-excess before, and how many
features each lowers and raises of how many had excess. Runs the ``eval`` logs of
``bench_gap_blind.py``; one trial costs what a blind trial costs (2-4 min).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_gap_blind as blind  # noqa: E402
from _common import logged_eval_trial, rerun_trials  # noqa: E402

import sknarx.gap.core as core  # noqa: E402
from sknarx.gap import diagnose  # noqa: E402

LOG = blind.RESULTS / "gap_breadth_split.jsonl"
KEYS = ("effect", "shrink", "log_shrink", "heldout_gap_after", "score", "log_gain",
        "log_harm", "log_total", "n_lowered", "n_raised", "n_with_excess")


def split(cmp0, cmp):
    """Log-excess gained and given back by the comparison table ``cmp`` against
    ``cmp0``, and how many features each way."""
    b = cmp0.set_index(core._KEY)["excess"]
    lb = np.log1p(b)
    la = np.log1p(cmp.set_index(core._KEY)["excess"].reindex(b.index).fillna(0.0))
    d = lb - la
    return {"log_gain": float(d.clip(lower=0).sum()), "log_harm": float((-d).clip(lower=0).sum()),
            "log_total": float(lb.sum()), "n_lowered": int((d > 1e-9).sum()),
            "n_raised": int((d < -1e-9).sum()), "n_with_excess": int((b > 0).sum())}


def _ranked_with_split(rank):
    """:func:`sknarx.gap.core.rank` with each entry's :func:`split` added (read only)."""
    def ranked(fits, E0, cmp0):
        out = rank(fits, E0, cmp0)
        for r in out:
            if r["_cmp"] is not None:
                r.update(split(cmp0, r["_cmp"]))
        return out
    return ranked


def run(family, seed):
    logged = logged_eval_trial(family, seed)
    if logged is None:
        raise SystemExit(f"bench_gap_breadth: no logged evaluation trial {family}:{seed} in "
                         f"{blind.RESULTS}; run bench_gap_blind.py first")
    measured, _, _, _ = blind.make_family_trial(logged["kind"], seed, family)
    # the blind run's search settings (its main's ``base``)
    settings = blind.search_settings()
    rank, core.rank = core.rank, _ranked_with_split(core.rank)
    try:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = diagnose(measured, settings=settings, exhaustive=True)
    finally:
        core.rank = rank
    return {"family": family, "seed": seed, "kind": logged["kind"],
            "e0": d["gap_before"]["per_feature"], "logged_e0": logged["e0"],
            "seconds": time.perf_counter() - t, "commit": blind.git_commit(),
            "ranking": [{k: r.get(k) for k in KEYS} for r in d["ranking"]],
            "logged_ranking": [{k: r[k] for k in ("effect", "shrink", "log_shrink")}
                               for r in logged["ranking"]]}


def show(rec):
    print(f"{rec['family']} {rec['seed']} {rec['kind']}: gap {rec['e0']:.3f} per feature "
          f"(logged {rec['logged_e0']:.3f})")
    print(f"  {'candidate':36s} {'shrink':>6s} {'logged':>6s} {'log sh':>6s} {'gain':>6s} "
          f"{'harm':>6s} {'total':>6s} lowered/raised/with excess")
    logged = {json.dumps(r["effect"]): r["shrink"] for r in rec["logged_ranking"]}
    for r in rec["ranking"][:4]:
        if r.get("log_gain") is None:
            continue
        name = json.dumps(r["effect"])
        print(f"  {name:36s} {r['shrink']:6.3f} {logged.get(name, float('nan')):6.3f} "
              f"{r['log_shrink']:6.2f} {r['log_gain']:6.1f} {r['log_harm']:6.1f} "
              f"{r['log_total']:6.1f} {r['n_lowered']}/{r['n_raised']}/{r['n_with_excess']}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trials", nargs="+", metavar="FAMILY:SEED")
    args = ap.parse_args(argv)
    for rec in rerun_trials(ap, args.trials, blind.FAMILIES, LOG, run):
        show(rec)


if __name__ == "__main__":
    main()
