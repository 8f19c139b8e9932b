"""Cost of one gap diagnosis of a 6-channel, 19-speed sweep against the whole library,
with nominal updating, on sweeps from each plant family.

Run: ``python benchmarks/bench_gap_cost.py [--families own,second,ross] [--repeat N]
[--kinds crack,none]`` (writes ``benchmarks/results/bench_gap_cost.json``).
Target (issue #13): at most 3 minutes on this 2-core machine. The numba kernels are
compiled once per process; the first-call compile time is reported separately. Stop
other jobs first: on a shared machine the figure is only as good as the idle cores.
The sweeps are the blind benchmark's trials (``plants.families``) with 19 speed steps
instead of 10, channels ``xO1 yO1 xA yA xB yB``.
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
from plants import families  # noqa: E402

from sknarx.gap import diagnose  # noqa: E402

SPEEDS_19 = tuple(np.linspace(81.7, 276.5, 19).round(4))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="own,second,ross")
    ap.add_argument("--kinds", default="crack,none,runout+crack",
                    help="withheld effects, comma-separated ('none', a name, a+b)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs of each trial (the machine is shared: the median is quoted)")
    args = ap.parse_args()
    # the trials' speed grid: 19 steps (the families read it at call time)
    families.SPEEDS = SPEEDS_19
    warm, *_ = families.make_family_trial("crack", 1, "own")
    t = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        diagnose(warm[warm.speed.isin(SPEEDS_19[:4])], candidates=("crack",))
    compile_s = time.perf_counter() - t
    rows, results = [], []
    for fam in args.families.split(","):
        for i, k in enumerate(args.kinds.split(",")):
            kind = None if k == "none" else (tuple(k.split("+")) if "+" in k else k)
            measured, truth, _, _ = families.make_family_trial(kind, 21 + i, fam)
            times = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    d = diagnose(measured)
                times.append(time.perf_counter() - t)
            dt = float(np.median(times))
            results.append({"family": fam, "truth": truth["kind"], "verdict": d["verdict"],
                            "seconds": dt, "runs_s": times, "shrink": d["shrink"]})
            rows.append([fam, str(truth["kind"]), str(d["verdict"]), f"{dt:.0f} s",
                         f"{min(times):.0f}-{max(times):.0f} s", "<= 180 s"])
            print(rows[-1], flush=True)
    table(rows, ["family", "withheld", "verdict", "19-speed diagnosis (median)", "range",
                 "target"])
    write_json("bench_gap_cost", {"speeds": len(SPEEDS_19), "channels": list(families.CHANNELS),
                                  "samples_per_step": 1000, "repeat": args.repeat,
                                  "compile_and_warmup_s": compile_s, "runs": results,
                                  "median_s": float(np.median([r["seconds"] for r in results])),
                                  "max_s": float(max(max(r["runs_s"]) for r in results)),
                                  "target_s": 180})


if __name__ == "__main__":
    main()
