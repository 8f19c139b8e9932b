"""Diagnose logged blind trials again with the package of another commit.

Run, e.g.: ``python benchmarks/rediagnose_at_commit.py --commit ed0d201 --report
results/bench_gap_blind_67000_af72500.json --logged af72500 --second-pass
second:67005 second:67040`` (each trial about 3 minutes; ``--jobs 2`` runs two at once;
resumable: each finished trial is appended to ``results/gap_blind_at_commit.jsonl``;
writes ``results/gap_rediagnosed_at_COMMIT.json``).

A blind run's trials are diagnosed by the package of the commit it ran at. Whether a
later run's misses come from the change it tried or from its draw is answered by the
other side: the same plants (the same family, seed and effect, generated again) diagnosed
by the package of an earlier commit, with the search settings of that commit's
``bench_gap_blind.search_settings``. The commit is checked out in a git worktree beside
the system's temporary files and each trial runs there in its own process, so nothing of
this checkout's package is mixed in. Both sides are decided by the same rule: the frozen
thresholds of ``--report`` (the run the trials were logged in) with this checkout's
``bench_gap_blind.verdict``. The commit's ``bench_gap_blind.run_trial`` must take
``(kind, seed, family, settings, exhaustive, readings, second_pass)``, as it has since
the 61000 run.

Analysis of trials already read: it explains a score, it is never one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402
    RESULTS,
    append_log,
    logged_eval_trial,
    read_log,
    table,
    trial_keys,
    write_json,
)
from bench_gap_blind import (  # noqa: E402
    FAMILIES,
    read_member_gaps,
    right,
    truth_label,
    verdict,
    with_cached_member_gap,
)
from rescore_gap_blind import frozen_thresholds  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
#: every trial diagnosed at another commit, each record with its commit and passes
LOG = RESULTS / "gap_blind_at_commit.jsonl"
#: what each trial's process runs, in the commit's ``benchmarks/``: one trial diagnosed,
#: its record printed on the last line
CHILD = """
import json, sys
import bench_gap_blind as b
kind = json.loads(sys.argv[1])
kind = tuple(kind) if isinstance(kind, list) else kind
r = b.run_trial(kind, int(sys.argv[2]), sys.argv[3], b.search_settings(), True, None,
                sys.argv[4] == "1")
r["commit"], r["code"] = b.git_commit(), b.code_hash()
print("RECORD " + json.dumps(r, default=float))
"""
#: one BLAS thread a process: the trials run side by side on the machine's cores
ONE_THREAD = {k: "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}


def resolve(commit: str) -> str | None:
    """The full hash of ``commit`` in this repository; None where git does not know it
    (a typo, or a shallow clone: its logged trials are still found by their prefix)."""
    try:
        got = subprocess.run(["git", "rev-parse", "--verify", "--quiet",
                              f"{commit}^{{commit}}"], cwd=REPO, capture_output=True, text=True)
    except OSError:
        return None
    return got.stdout.strip() if got.returncode == 0 else None


def worktree(sha: str) -> Path:
    """A checkout of ``sha`` in a git worktree under the temporary folder (made once,
    reused by later runs)."""
    path = Path(tempfile.gettempdir()) / f"sknarx-at-{sha[:12]}"
    if not (path / "benchmarks" / "bench_gap_blind.py").exists():
        subprocess.run(["git", "worktree", "add", "--detach", "--force", str(path), sha],
                       cwd=REPO, check=True, capture_output=True)
    return path


def diagnose_at(tree: Path, kind, seed: int, family: str, second_pass: bool) -> dict:
    """Trial ``family:seed`` of ``kind`` diagnosed by the package checked out at
    ``tree``, in its own process."""
    env = {**os.environ, **ONE_THREAD, "MPLBACKEND": "Agg", "PYTHONPATH": str(tree)}
    got = subprocess.run([sys.executable, "-c", CHILD, json.dumps(kind), str(seed), family,
                          "1" if second_pass else "0"],
                         cwd=tree / "benchmarks", env=env, capture_output=True, text=True)
    lines = [ln for ln in got.stdout.splitlines() if ln.startswith("RECORD ")]
    if got.returncode or not lines:
        raise RuntimeError(f"{family}:{seed} at {tree.name} failed:\n{got.stderr[-2000:]}")
    return json.loads(lines[-1][len("RECORD "):])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("trials", nargs="+", metavar="FAMILY:SEED")
    ap.add_argument("--commit", required=True, help="the package to diagnose them with")
    ap.add_argument("--report", required=True,
                    help="the bench_gap_blind report of the run that logged the trials "
                         "(its frozen thresholds decide both sides)")
    ap.add_argument("--logged", required=True,
                    help="the commit (prefix) the trials were logged at")
    ap.add_argument("--second-pass", action="store_true",
                    help="measure each trial in two passes, as the logged run did")
    ap.add_argument("--jobs", type=int, default=1, help="trials run at once")
    args = ap.parse_args(argv)
    frozen = frozen_thresholds(args.report, ap)
    keys = trial_keys(ap, args.trials, FAMILIES)
    member_gaps = read_member_gaps()
    logged = {}
    for family, seed in keys:
        rec = logged_eval_trial(family, seed, [args.logged])
        if rec is None:
            ap.error(f"no logged trial {family}:{seed} of {args.logged}")
        logged[family, seed] = with_cached_member_gap(rec, member_gaps)
    sha = resolve(args.commit)
    commit = sha or args.commit
    done = {(r["family"], r["seed"]): r for r in read_log(LOG)
            if r["commit"].startswith(commit) and r.get("second_pass") == args.second_pass}
    todo = [k for k in keys if k not in done]
    if todo:
        if sha is None:
            ap.error(f"--commit: {args.commit!r} is no commit of {REPO}; give a hash or a "
                     "tag")
        tree = worktree(sha)
        lock = threading.Lock()

        def one(key):
            family, seed = key
            rec = {**diagnose_at(tree, logged[key]["kind"], seed, family, args.second_pass),
                   "second_pass": args.second_pass}
            with lock:
                append_log(LOG, rec)
                print(f"  {family}:{seed} " + (f"skipped ({rec['skipped']})" if "skipped" in rec
                                               else f"done ({rec['seconds']:.0f} s)"),
                      flush=True)
            return key, rec

        print(f"diagnosing {len(todo)} trial(s) at {commit[:7]} ({tree})", flush=True)
        with ThreadPoolExecutor(max(1, args.jobs)) as pool:
            done.update(pool.map(one, todo))
    rows, out = [], []
    for key in keys:
        # a pair member's visibility beside its partner is the plant's, the same on
        # both sides
        before = logged[key]
        at = {**done[key], **({"member_gap": before["member_gap"]}
                              if "member_gap" in before else {})}
        # the commit's plant may fail where the logged run's did not (its integrator)
        skipped = "skipped" in at
        row = {"trial": f"{key[0]}:{key[1]}", "truth": truth_label(before, frozen),
               "logged": verdict(before, frozen)[0],
               "at_commit": "skipped" if skipped else verdict(at, frozen)[0],
               "right_logged": right(before, frozen),
               "right_at_commit": not skipped and right(at, frozen),
               "e0_logged": before["e0"], "e0_at_commit": None if skipped else at["e0"]}
        out.append(row)
        rows.append([row["trial"], json.dumps(row["truth"]), json.dumps(row["logged"]),
                     json.dumps(row["at_commit"]), f"{row['e0_logged']:.2f}",
                     "-" if skipped else f"{row['e0_at_commit']:.2f}"])
    table(rows, ["trial", "truth", f"verdict at {args.logged}", f"verdict at {commit[:7]}",
                 "e0 logged", "e0 at commit"])
    changed = [r["trial"] for r in out if r["logged"] != r["at_commit"]]
    print("verdicts that differ:", ", ".join(changed) or "none")
    write_json(f"gap_rediagnosed_at_{commit[:7]}",
               {"command": "python benchmarks/rediagnose_at_commit.py "
                           + " ".join(sys.argv[1:] if argv is None else argv),
                "commit": done[keys[0]]["commit"], "report": args.report, "logged": args.logged,
                "trials": out, "changed": changed})


if __name__ == "__main__":
    main()
