"""Cost of a whole-library gap diagnosis of a 6-channel, 19-speed sweep, side by side with
the same diagnosis by another checkout of sknarx (the previous commit).

Run: ``python benchmarks/bench_gap_cost.py [--families own,second,ross] [--kinds
crack,none,runout+crack] [--peer PATH] [--summary]`` (writes
``benchmarks/results/bench_gap_cost.json``). ``--peer`` is a checkout of the code to
compare with (``git worktree add ../peer COMMIT``): each sweep is diagnosed by it in a
separate process (its own package on ``PYTHONPATH``) right after this checkout's run,
and the table gives both times, their ratio, both verdicts and shrinks. The sweeps are
the blind plants' trials (:mod:`validation.plants.families`) with 19 speed steps;
each process compiles the numba kernels once before timing. Where the time goes is
given per phase (updating, nuisances, candidates, pairs). Stop other jobs first: the
figures are only as good as the idle cores.
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import summary_flag, table, write_json  # noqa: E402, I001

import numpy as np  # noqa: E402

SPEEDS_19 = tuple(np.linspace(81.7, 276.5, 19).round(4))

#: what a checkout runs on a pickled sweep: warm up, diagnose once, print the document's
#: verdict, shrink and each phase's time as JSON (old and new APIs alike)
RUNNER = r"""
import json, pickle, sys, time
from sknarx.gap import diagnose
measured = pickle.load(open(sys.argv[1], "rb"))
diagnose(measured[measured.speed.isin(sorted(measured.speed.unique())[:4])],
         candidates=("crack",))
marks = []
t = time.perf_counter()
d = diagnose(measured, progress=lambda m: marks.append((m, time.perf_counter())))
total = time.perf_counter() - t
phases, last = {}, t
for msg, at in marks:
    phases[msg] = at - last
    last = at
import pathlib, sknarx
print(json.dumps({"seconds": total, "verdict": d["verdict"], "shrink": d["shrink"],
                  "phases_s": phases,
                  "package": str(pathlib.Path(sknarx.__file__).resolve().parents[1])},
                 default=str))
"""


def run_in(checkout, sweep_path) -> dict:
    """Diagnose the pickled sweep with the package of ``checkout`` in a new process."""
    env = dict(os.environ, PYTHONPATH=str(checkout), OPENBLAS_NUM_THREADS="1")
    # run in the checkout: ``python -c`` puts the working directory first on the path,
    # ahead of PYTHONPATH, so a run started elsewhere would import that folder's package
    out = subprocess.run([sys.executable, "-c", RUNNER, str(sweep_path)], env=env,
                         cwd=str(checkout), capture_output=True, text=True, check=True)
    if f'"package": "{Path(checkout).resolve()}' not in out.stdout:
        raise RuntimeError(f"the run imported another sknarx than {checkout}: {out.stdout}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="own,second,ross")
    ap.add_argument("--kinds", default="crack,none,runout+crack",
                    help="withheld effects, comma-separated ('none', a name, a+b)")
    ap.add_argument("--seed", type=int, default=21,
                    help="first trial seed (each kind the next; a plant that fails on a "
                         "seed is drawn 100 seeds on)")
    ap.add_argument("--peer", help="a checkout of the code to compare with")
    summary_flag(ap)
    args = ap.parse_args(argv)
    if args.peer and not (Path(args.peer) / "sknarx" / "__init__.py").exists():
        ap.error(f"--peer {args.peer} is not a checkout of sknarx (no sknarx/__init__.py)")
    from validation.plants import families
    from validation.trials import PLANT_FAILURES

    families.SPEEDS = SPEEDS_19  # the families read the speed grid at call time
    here = Path(__file__).resolve().parents[1]
    rows, runs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for fam in args.families.split(","):
            for i, k in enumerate(args.kinds.split(",")):
                kind = None if k == "none" else (tuple(k.split("+")) if "+" in k else k)
                measured = None
                for seed in range(args.seed + i, args.seed + i + 400, 100):
                    try:
                        measured, truth, _, _ = families.make_family_trial(kind, seed, fam)
                        break
                    except PLANT_FAILURES as exc:
                        print(f"{fam} {k} seed {seed}: the plant failed ({exc})", flush=True)
                if measured is None:
                    continue
                path = Path(tmp) / f"{fam}-{k}.pkl"
                path.write_bytes(pickle.dumps(measured))
                t = time.perf_counter()
                now = run_in(here, path)
                peer = run_in(args.peer, path) if args.peer else None
                run = {"family": fam, "truth": truth["kind"], "seed": seed, "now": now,
                       "peer": peer, "wall_s": time.perf_counter() - t}
                if peer:
                    run["ratio"] = peer["seconds"] / now["seconds"]
                runs.append(run)
                rows.append([fam, f"{k} ({seed})", f"{now['seconds']:.0f} s",
                             f"{now['verdict']} ({now['shrink']:.2f})",
                             *( [f"{peer['seconds']:.0f} s",
                                 f"{peer['verdict']} ({peer['shrink']:.2f})",
                                 f"x{run['ratio']:.2f}"] if peer else [])])
                print(rows[-1], flush=True)
                print("  phases: " + ", ".join(f"{m} {s:.0f} s"
                                               for m, s in now["phases_s"].items()), flush=True)
    heads = ["family", "withheld (seed)", "this checkout", "verdict (shrink)"]
    if args.peer:
        heads += ["peer", "peer verdict (shrink)", "peer / this"]
    table(rows, heads)
    times = [r["now"]["seconds"] for r in runs]
    write_json("bench_gap_cost", {
        "speeds": len(SPEEDS_19), "channels": list(families.CHANNELS),
        "samples_per_step": 1000, "peer": args.peer, "runs": runs,
        "median_s": float(np.median(times)) if times else None,
        "max_s": float(max(times)) if times else None,
        "median_ratio": float(np.median([r["ratio"] for r in runs])) if args.peer else None},
        args.summary)


if __name__ == "__main__":
    main()
