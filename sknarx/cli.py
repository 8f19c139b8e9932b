"""Command line: ``sknarx paper --out DIR`` (and ``python -m sknarx paper``)."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from pathlib import Path

# Two cores: keep BLAS single-threaded under the process-level parallelism we use.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def _paper(args) -> int:
    from .reproduce import PaperCase, run_study
    from .reproduce.report import write_outputs

    case = PaperCase(n_jobs=args.n_jobs)
    if args.quick:
        case = PaperCase(n_jobs=args.n_jobs, n_samples=8192, curve_speeds=tuple(
            range(50, 321, 10)), cv_samples=4096, validation_samples=8192)
    start = time.perf_counter()
    steps = ["simulator", "steady sweep", "from-rest sweep", "identification", "validation",
             "cross-validation", "run-up"]
    bar = None
    if not args.quiet:
        try:
            from tqdm.auto import tqdm

            bar = tqdm(total=len(steps) + 1, desc="sknarx paper", unit="step")
        except ImportError:  # pragma: no cover
            bar = None

    def progress(name):
        if bar is not None:
            bar.set_postfix_str(name[:40])
            bar.update(1)
        elif not args.quiet:
            print(f"[{time.perf_counter() - start:6.1f} s] {name}", flush=True)

    study = run_study(case, progress=progress)
    command = "sknarx " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    metrics = write_outputs(study, args.out, command)
    progress("figures and report")
    if bar is not None:
        bar.close()
    out = Path(args.out)
    val = metrics["validation"]
    print(f"\nWrote {out / 'report.html'} (open it first), metrics.json, figures, tables, "
          "model.json")
    print(f"critical speed {metrics['critical_speed']:.1f} rad/s (paper 144.5); "
          f"{len(metrics['selected_terms'])} terms, total AERR {metrics['aerr_total']:.6f} %")
    for v in val:
        print(f"  validation {v['speed']:g} rad/s: NRMSE {100 * float(v['nrmse']):.2f} %, "
              f"1x error {100 * float(v['amp1x_rel_error']):.2f} %")
    print(f"total {time.perf_counter() - start:.0f} s")
    return 0


def _gap(args) -> int:
    from .gap import diagnose, load_measured
    from .gap.report import write_gap_outputs
    from .rotor.config import load_config, paper_rotor_from_config

    cfg = load_config(args.rotor) if args.rotor else {}
    model = cfg.get("rotor", {}).get("model", "paper")
    command = "sknarx " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    if model != "paper" or _is_order_domain(args.measured):
        from .gap.orderdomain import diagnose_order_domain

        doc = diagnose_order_domain(args.measured, cfg, args.out, command,
                                    quiet=args.quiet)
    else:
        from .gap.narx_view import narx_view_of

        base = paper_rotor_from_config(cfg)
        measured = load_measured(args.measured)

        def progress(msg):
            if not args.quiet:
                print(f"[{time.perf_counter() - start:6.1f} s] {msg}", flush=True)

        start = time.perf_counter()
        kw = {"candidates": tuple(args.candidates)} if args.candidates else {}
        result = diagnose(measured, base=base, channels=args.channels, progress=progress, **kw)
        narx = None
        if not args.no_narx:
            narx = narx_view_of(result, measured, base)
            progress("NARX view")
        doc = write_gap_outputs(result, args.out, command, narx)
    out = Path(args.out)
    print(f"verdict: {doc['verdict']}; held-out gap removed: {100 * float(doc['shrink']):.0f} %")
    print(f"wrote {out / 'report.html'} and {out / 'diagnosis.json'}")
    return 0


def _is_order_domain(path) -> bool:
    import pandas as pd

    p = Path(path)
    if p.suffix != ".csv":
        return False
    cols = pd.read_csv(p, nrows=0).columns
    return "t" not in cols and any(c.startswith("amp_") for c in cols)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="sknarx", description="Speed-scheduled NARX models of rotor-bearing systems.")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("paper", help="reproduce Jin et al. 2022, Case 1, end to end")
    p.add_argument("--out", required=True, help="output directory (created)")
    p.add_argument("--n-jobs", type=int, default=2, help="parallel simulation workers")
    p.add_argument("--quick", action="store_true",
                   help="short records for a fast smoke run (not the paper's settings)")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=_paper)
    g = sub.add_parser("gap", help="diagnose the sim-to-real gap of measured data")
    g.add_argument("--measured", required=True, help="measured data file (.csv or .parquet)")
    g.add_argument("--rotor", help="rotor description (.toml, .yaml or .json); default: "
                   "the paper's rotor")
    g.add_argument("--out", required=True, help="output directory (created)")
    g.add_argument("--channels", nargs="+", help="channels to use (default: all DOF columns)")
    g.add_argument("--candidates", nargs="+", help="effects to search (default: the library)")
    g.add_argument("--no-narx", action="store_true", help="skip the NARX view")
    g.add_argument("--quiet", action="store_true")
    g.set_defaults(func=_gap)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
