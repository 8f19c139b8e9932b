"""Run blind trials: ``python -m validation.run --seeds 71000 --trials 68 --out DIR``.

Each family's trials (:func:`validation.trials.plan`) are diagnosed by the package as
installed, through joblib (``--n-jobs``; ``--scheduler ADDRESS`` sends them to a
dask.distributed cluster, so a thousand-trial run is a cluster job). Every finished
trial is kept at once in ``DIR/<family>.jsonl.gz``, rewritten whole or not at all: a
stopped run started again resumes, and a trial logged by other diagnosis code (its
``code`` key: the package's gap and rotor code, the plants' and the rule's values) is
run again. ``python -m validation.score DIR`` scores the run.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import logging
import sys
from pathlib import Path

from joblib import Parallel, delayed, parallel_config
from tqdm.auto import tqdm

from .plants.families import FAMILIES
from .trials import plan, run_trial

__all__ = ["code_key", "read_log", "write_log", "main"]

logger = logging.getLogger("validation")


def code_key() -> str:
    """What a trial's outcome depends on: the diagnosis's and the plants' code and the
    verdict rule's and search budget's values (first 16 hex digits of a SHA-256)."""
    import sknarx
    from sknarx.gap import SearchBudget, VerdictRule

    root = Path(sknarx.__file__).parent
    h = hashlib.sha256()
    for path in sorted([*(root / "gap").glob("*.py"), *(root / "rotor").glob("*.py"),
                        *(Path(__file__).parent / "plants").glob("*.py")]):
        h.update(path.read_bytes())
    h.update(json.dumps([VerdictRule().to_dict(), SearchBudget().to_dict()]).encode())
    return h.hexdigest()[:16]


def read_log(path) -> list:
    """The records of a trial log (``.jsonl.gz``; none for a missing file)."""
    path = Path(path)
    if not path.exists():
        return []
    with gzip.open(path, "rt") as f:
        return [json.loads(line) for line in f if line.strip()]


def write_log(path, records) -> None:
    """Write ``records`` to ``path`` (``.jsonl.gz``, by seed) whole or not at all."""
    from sknarx._atomic import write_atomic

    lines = "".join(json.dumps(r, default=str) + "\n"
                    for r in sorted(records, key=lambda r: r["seed"]))

    def write(tmp):
        # a fixed mtime: the same records give the same bytes
        with open(tmp, "wb") as raw, gzip.GzipFile(filename="", fileobj=raw, mode="wb",
                                                   mtime=0) as f:
            f.write(lines.encode())

    write_atomic(path, write)


def _one(kind, seed, family, code):
    rec = run_trial(kind, seed, family)
    rec["code"] = code
    return rec


def run_family(family, trials, out: Path, n_jobs, code) -> list:
    """The family's ``trials`` (``(kind, seed)``) logged in ``out``, running those not
    yet logged by this code."""
    log = out / f"{family}.jsonl.gz"
    done = {r["seed"]: r for r in read_log(log) if r.get("code") == code}
    stale = len(read_log(log)) - len(done)
    if stale:
        logger.info("%s: %d trial(s) logged by other code are run again", family, stale)
    todo = [(k, s) for k, s in trials if s not in done]
    logger.info("%s: %d of %d trial(s) to run", family, len(todo), len(trials))
    results = Parallel(n_jobs=n_jobs, return_as="generator_unordered")(
        delayed(_one)(kind, seed, family, code) for kind, seed in todo)
    for rec in tqdm(results, total=len(todo), desc=family, unit="trial", file=sys.stderr):
        done[rec["seed"]] = rec
        write_log(log, done.values())
        if "skipped" in rec:
            logger.info("%s seed %d: skipped (%s)", family, rec["seed"], rec["skipped"])
        else:
            logger.info("%s seed %d %s: %s in %.0f s", family, rec["seed"], rec["kind"],
                        rec["verdict"], rec["seconds"])
    return [r for r in done.values() if "skipped" not in r]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.run",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--families", default="ross,second",
                    help=f"comma-separated, from {', '.join(FAMILIES)} (default ross,second)")
    ap.add_argument("--seeds", type=int, required=True, help="first seed of the run")
    ap.add_argument("--trials", type=int, default=68, help="trials per family (default 68)")
    ap.add_argument("--out", required=True, help="the run's folder (created; resumed)")
    ap.add_argument("--n-jobs", type=int, default=None,
                    help="trials in parallel (default: one at a time; -1 every CPU)")
    ap.add_argument("--scheduler", metavar="ADDRESS",
                    help="a dask.distributed scheduler to run the trials on")
    args = ap.parse_args(argv)
    families = args.families.split(",")
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        ap.error(f"unknown family {', '.join(unknown)}; the families are "
                 f"{', '.join(FAMILIES)}")
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    code = code_key()
    backend = {}
    if args.scheduler:
        from dask.distributed import Client

        client = Client(args.scheduler)
        backend = {"backend": "dask"}
        logger.info("running on %s", client)
    with parallel_config(**backend):
        for family in families:
            run_family(family, plan(args.trials, args.seeds, family), out, args.n_jobs,
                       code)
    logger.info("scored by: python -m validation.score %s", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
