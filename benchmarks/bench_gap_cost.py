"""Cost of one gap diagnosis of a 19-speed sweep against the whole library.

Run: ``python benchmarks/bench_gap_cost.py [--repeat N]`` (writes
``benchmarks/results/bench_gap_cost.json``).
Target: at most 3 minutes on this 2-core machine. The numba kernels are compiled
once per process; the first-call compile time is reported separately. Stop other
jobs first: on a shared machine the figure is only as good as the idle cores.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
from _common import table, write_json  # noqa: E402

from sknarx.gap import diagnose  # noqa: E402
from sknarx.gap.synthetic import make_trial  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2,
                    help="runs of each trial (the machine is shared: the median is quoted)")
    args = ap.parse_args()
    speeds = tuple(np.linspace(81.7, 276.5, 19).round(4))
    warm, _ = make_trial("crack", 1, speeds=speeds[:4])
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        diagnose(warm, candidates=("crack",))
    compile_s = time.perf_counter() - t
    rows, results = [], []
    # a single effect, a dominant one, none, and a pair (the pair search runs)
    for kind, seed in (("crack", 21), ("runout", 22), (None, 23), (("runout", "crack"), 24)):
        measured, truth = make_trial(kind, seed, speeds=speeds, n_samples=1000)
        times = []
        for _ in range(args.repeat):
            t = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                d = diagnose(measured)
            times.append(time.perf_counter() - t)
        dt = float(np.median(times))
        results.append({"truth": truth["kind"], "verdict": d["verdict"], "seconds": dt,
                        "runs_s": times, "shrink": d["shrink"]})
        rows.append([str(truth["kind"]), str(d["verdict"]), f"{dt:.0f} s",
                     f"{min(times):.0f}-{max(times):.0f} s", "<= 180 s"])
    table(rows, ["withheld", "verdict", "19-speed diagnosis (median)", "range", "target"])
    write_json("bench_gap_cost", {"speeds": len(speeds), "samples_per_step": 1000,
                                  "repeat": args.repeat,
                                  "compile_and_warmup_s": compile_s, "runs": results,
                                  "median_s": float(np.median([r["seconds"] for r in results])),
                                  "max_s": float(max(max(r["runs_s"]) for r in results)),
                                  "target_s": 180})


if __name__ == "__main__":
    main()
