"""Shared helpers of the benchmarks: timing medians, tables, JSON output, BLAS control."""

from __future__ import annotations

import functools
import json
import os
import platform
import statistics
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

# after the thread settings: it imports numpy
from sknarx.io import write_text_atomic  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
#: how a plant's own run fails (ROSS's Newton iteration raises a bare Warning): the
#: benchmarks skip or redraw such a trial instead of diagnosing a sweep that is not there
#: (here, not in plants/: the plants' code is hashed into the blind run's log key)
PLANT_FAILURES = (FloatingPointError, RuntimeError, Warning)


def timeit(fn, repeat=5):
    """Median and all wall times (s) of ``repeat`` calls; returns the last result too."""
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times, out


def machine():
    import subprocess

    from threadpoolctl import threadpool_info

    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent).stdout.strip()
    except OSError:  # pragma: no cover
        commit = ""
    return {
        "git_commit": commit,
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "blas": [{k: i.get(k) for k in ("internal_api", "num_threads", "version")}
                 for i in threadpool_info()],
    }


#: the machine-speed reference: bench_simulator's peer (scipy's RK45 at rtol 1e-6 on a
#: NumPy right-hand side of the paper rotor, 2 s at 250 rad/s sampled at 1 kHz), a
#: workload whose code has not changed in substance since it was first timed (one
#: per-bearing lookup per evaluation added since), so its time tracks the machine, not
#: the package; its earliest timing on record is the baseline
REFERENCE_RUN = {"omega": 250.0, "duration_s": 2.0, "fs": 1000.0, "rtol": 1e-6}
REFERENCE_BASELINE = "bench_simulator_2463907.json"


@functools.cache
def _reference_simulator():
    """The reference's rotor, its static equilibrium already solved: the baseline timed
    the integration alone, on a simulator that had run before."""
    from sknarx.rotor import RotorBearingSimulator

    sim = RotorBearingSimulator()
    sim.static_equilibrium()
    return sim


def reference_workload():
    """Run the machine-speed reference once; returns ``(outputs, solver result)``."""
    from sknarx.rotor.reference import solve_reference

    r = REFERENCE_RUN
    return solve_reference(_reference_simulator(), r["omega"], r["duration_s"], r["fs"],
                           method="RK45", rtol=r["rtol"])


def time_reference(repeat=1):
    """:func:`timeit` of :func:`reference_workload`, its simulator built before the first
    timed call (the cache alone would build it inside that call)."""
    _reference_simulator()
    return timeit(reference_workload, repeat)


def machine_reference(runs_s):
    """This machine's speed against the baseline's, from ``runs_s`` (wall times of
    :func:`reference_workload`): their median, the baseline's (from
    ``results/REFERENCE_BASELINE``) and the ratio ``factor`` (above 1: slower than
    then). Divide a time by ``factor`` to quote it at the baseline machine's speed."""
    now = statistics.median(runs_s)
    base = json.loads((RESULTS / REFERENCE_BASELINE).read_text())
    then = base["one_speed"]["solve_ivp_rk45_median_s"]
    return {"workload": "scipy RK45 (rtol 1e-6), NumPy right-hand side, paper rotor, "
                        "2 s at 250 rad/s, 1 kHz (bench_simulator's peer)",
            "seconds": now, "runs_s": list(runs_s), "baseline_s": then,
            "baseline_from": f"results/{REFERENCE_BASELINE} (commit "
                             f"{base['machine']['git_commit'][:7]})",
            "factor": now / then}


def table(rows, headers):
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(headers)]
    line = "  ".join(str(h).ljust(w) for h, w in zip(headers, widths, strict=True))
    print(line)
    print("-" * len(line))
    for r in rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)))


def write_json(name, payload):
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {"machine": machine(), **payload}
    # a report stopped mid-write would leave a truncated file its pinned tests read
    write_text_atomic(path, json.dumps(payload, indent=1, default=float))
    print(f"\nwrote {path}")
    return path


def setting_overrides(items, fields, ap, flag, example,
                      fields_are="a field of DiagnosisSettings"):
    """``field=value`` pairs from the command line as keywords, for the benchmarks that
    change a :class:`~sknarx.gap.DiagnosisSettings` from theirs (one parser, one syntax).

    Each of ``items`` holds one pair or several separated by commas; a pair ends only at a
    comma before the next ``field=``, so a tuple keeps its commas (``order_floors_z2=(2.5,
    1.8, 1.7)``, or without parentheses ``order_floors_z2=2.5,1.8,1.7``). Values are Python
    literals (``None``, ``True``, ``64``, ``0.3``). A field not in ``fields`` or a value that
    is not a literal is ``ap``'s usage error naming ``flag``, what the fields are
    (``fields_are``) and, as a model, ``example``."""
    import ast
    import re

    out = {}
    for item in (p for text in items for p in re.split(r",(?=\s*\w+\s*=)", text) if p):
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or key not in fields:
            ap.error(f"{flag}: {item!r} is not field=value with field {fields_are} "
                     f"(e.g. {example})")
        try:
            out[key] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            ap.error(f"{flag}: the value of {key} ({value.strip()!r}) is not a Python literal "
                     "(a number, True, False, None or a tuple)")
    return out


def read_log(*paths):
    """Every record of the JSON-lines logs ``paths``, in order (a missing log holds none):
    the benchmarks append each finished trial to one, so a stopped run resumes."""
    for path in paths:
        if Path(path).exists():
            for line in Path(path).read_text().splitlines():
                yield json.loads(line)


def append_log(path, record):
    """Append ``record`` to the JSON-lines log ``path`` as one line (its folder made)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as f:
        f.write(json.dumps(record, default=float) + "\n")


def trial_keys(ap, items, families):
    """``FAMILY:SEED`` ``items`` as ``(family, seed)`` pairs; a malformed item is ``ap``'s
    error."""
    keys = []
    for item in items:
        family, sep, seed = item.partition(":")
        if not sep or not seed.isdigit() or family not in families:
            ap.error(f"a trial is FAMILY:SEED with FAMILY one of {', '.join(families)}; "
                     f"got {item!r}")
        keys.append((family, int(seed)))
    return keys


def rerun_trials(ap, items, families, log, run):
    """Yield the records of ``FAMILY:SEED`` ``items`` in turn, each from the JSON-lines
    ``log`` if it is there, else ``run(family, seed)``'s, appended to it first: a re-run
    of logged trials that resumes. A malformed item is ``ap``'s error before any run."""
    keys = trial_keys(ap, items, families)
    done = {(r["family"], r["seed"]): r for r in read_log(log)}
    for key in keys:
        if key not in done:
            done[key] = run(*key)
            append_log(log, done[key])
        yield done[key]


def logged_eval_trial(family, seed, commits=None):
    """The last logged (not skipped) blind evaluation trial ``family:seed``, from a run of
    one of ``commits`` (prefixes; any when None); None if there is none."""
    rec = None
    for r in read_log(*sorted(RESULTS.glob(f"gap_blind_eval_{family}*.jsonl"))):
        if (r["seed"] == seed and "skipped" not in r
                and (commits is None or r.get("commit", "").startswith(tuple(commits)))):
            rec = r
    return rec
