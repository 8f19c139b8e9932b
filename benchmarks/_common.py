"""Shared helpers of the speed benchmarks: medians of wall times, a table, the JSON.

Every benchmark times the package and its named peer side by side in one run (the
machine is shared and hosts differ up to three times in speed, so only ratios and
medians of one run compare), prints a table and writes its JSON to
``benchmarks/results/`` (not committed); ``--summary`` also writes the committed
summary ``benchmarks/summaries/<name>.json``, the latest run's.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

# one BLAS thread per process: the code parallelises where it pays
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
SUMMARIES = HERE / "summaries"


def timeit(fn, repeat=5):
    """Median and all wall times (s) of ``repeat`` calls; returns the last result too."""
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times, out


def fit_cost(fit, repeat):
    """``fit()``'s median and all wall times (s) over ``repeat`` calls and the peak
    memory one more call traces (MB); returns the last fitted model and the figures."""
    import tracemalloc

    t, times, model = timeit(fit, repeat)
    tracemalloc.start()
    fit()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return model, {"fit_median_s": t, "fit_times_s": times, "peak_traced_mb": peak / 2**20}


def machine() -> dict:
    """Where and with what a benchmark ran: commit, Python, CPUs, BLAS, versions."""
    import subprocess

    from threadpoolctl import threadpool_info

    from sknarx._report import dependency_versions

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                cwd=HERE).stdout.strip()
    except OSError:  # pragma: no cover
        commit = ""
    return {"git_commit": commit, "python": platform.python_version(),
            "cpu_count": os.cpu_count(), "dependencies": dependency_versions(),
            "blas": [{k: i.get(k) for k in ("internal_api", "num_threads", "version")}
                     for i in threadpool_info()],
            "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]])}


def table(rows, headers):
    """Print ``rows`` under ``headers``, columns aligned."""
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(headers)]
    line = "  ".join(str(h).ljust(w) for h, w in zip(headers, widths, strict=True))
    print(line)
    print("-" * len(line))
    for r in rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)))


def write_json(name, payload, summary=False) -> Path:
    """Write ``results/<name>.json`` (and with ``summary`` the committed
    ``summaries/<name>.json``) whole or not at all, with :func:`machine`."""
    from sknarx.io import write_text_atomic

    text = json.dumps({"machine": machine(), **payload}, indent=1, default=float)
    RESULTS.mkdir(exist_ok=True)
    path = write_text_atomic(RESULTS / f"{name}.json", text)
    if summary:
        SUMMARIES.mkdir(exist_ok=True)
        write_text_atomic(SUMMARIES / f"{name}.json", text)
    print(f"\nwrote {path}" + (f" and {SUMMARIES / (name + '.json')}" if summary else ""))
    return path


def summary_flag(ap) -> None:
    """Add ``--summary`` to a benchmark's parser."""
    ap.add_argument("--summary", action="store_true",
                    help="also write the committed summary benchmarks/summaries/NAME.json")
