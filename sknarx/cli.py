"""Command line: ``sknarx paper``, ``sknarx gap`` and ``sknarx unbalance``.

Every mistake a user can make with their input (a missing or malformed file, wrong
columns, an unknown option value) ends in one line that names the problem and the
fix, with exit code 2; ``--debug`` shows the traceback instead. Progress and what
happens go to stderr through the ``sknarx`` logger (``--verbose``/``--quiet``).
"""

from __future__ import annotations

import argparse
import logging
import os
import shlex
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

logger = logging.getLogger("sknarx")

# The names are repeated here, not imported, so that ``--help`` and option checks do not
# import the numerical stack; a test keeps them equal to the library's.
EFFECTS = ("rub", "misalignment", "crack", "looseness", "clearance", "anisotropy", "runout",
           "speed-fluctuation")
CHANNELS = ("xO1", "yO1", "xO2", "yO2", "xA", "yA", "xB", "yB")
#: where ``sknarx gap`` keeps its finished steps inside ``--out`` until the outputs exist
CHECKPOINT_DIR = ".checkpoint"
#: set by :func:`console_main`: the process is the ``sknarx`` program, not a caller's
_AS_PROGRAM = False


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors that point at ``--help``."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def _command_line(argv) -> str:
    """The command that reproduces a run: ``sknarx`` and the arguments it was given."""
    return "sknarx " + " ".join(shlex.quote(str(a)) for a in argv)


def _check_out(path) -> Path:
    """The output folder, created and tried with a file before any work is done."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file; give a folder to write the results into.")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out, prefix=".sknarx-write-check-"):
            pass
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ValueError(f"--out {out}: cannot write there ({reason}); give a folder you "
                         "can create and write to.") from exc
    return out


def _paper(args) -> int:
    from ._progress import progress_bar
    from .reproduce import PaperCase, run_study
    from .reproduce.report import write_outputs
    from .reproduce.text import aerr_text

    out = _check_out(args.out)
    case = PaperCase(n_jobs=args.n_jobs)
    if args.quick:
        case = PaperCase(n_jobs=args.n_jobs, n_samples=8192, curve_speeds=tuple(
            range(50, 321, 10)), cv_samples=4096, validation_samples=8192)
    start = time.perf_counter()
    n_steps = 9  # the study's marked steps plus the report
    bar = progress_bar(total=n_steps, desc="sknarx paper", unit="step")

    def progress(name):
        bar.set_postfix_str(name[:40])
        bar.update(1)
        logger.debug("[%6.1f s] %s", time.perf_counter() - start, name)

    study = run_study(case, progress=progress)
    metrics = write_outputs(study, out, args.command_line)
    progress("figures and report")
    bar.close()
    val = metrics["validation"]
    print(f"Wrote {out / 'report.html'} (open it first), metrics.json, figures, tables, "
          "model.json")
    print(f"critical speed {metrics['critical_speed']:.1f} rad/s (paper 144.5); "
          f"{len(metrics['selected_terms'])} terms, total AERR {aerr_text(metrics['aerr_total'])}")
    for v in val:
        print(f"  validation {v['speed']:g} rad/s: NRMSE {100 * float(v['nrmse']):.2f} %, "
              f"1x error {100 * float(v['amp1x_rel_error']):.2f} %")
    print(f"total {time.perf_counter() - start:.0f} s")
    return 0


def _gap(args) -> int:
    from .gap import diagnose, load_measured
    from .gap.report import write_gap_outputs
    from .io import read_table
    from .rotor.config import load_config, paper_rotor_from_config

    cfg = load_config(args.rotor) if args.rotor else {}
    model = cfg.get("rotor", {}).get("model", "paper")
    if model not in ("paper", "beam"):
        raise ValueError(f"--rotor {args.rotor}: [rotor] model = {model!r}; give 'paper' (the "
                         "12-DOF paper rotor, time-series sweeps) or 'beam' (a beam rotor, "
                         "order-tracked 1x records).")
    header = read_table(args.measured, what="measured data", nrows=1)
    order_domain = "t" not in header.columns and any(c.startswith("amp_") for c in header)
    if order_domain and model == "paper":
        raise ValueError(f"--measured {args.measured} is an order-tracked (1x Bode) record: "
                         "it is diagnosed against a beam rotor file, --rotor FILE with "
                         "[rotor] model = 'beam' (see examples/rk4/rotor.toml); the paper's "
                         "rotor takes time-series sweeps (speed, t, a column per DOF).")
    if model == "beam":
        from .bode import diagnose_order_domain, write_bode_outputs

        if args.candidates or args.channels or args.no_update or args.second_pass:
            logger.warning("--candidates, --channels, --no-update and --second-pass apply "
                           "to time-series "
                           "sweeps; an order-domain (Bode) record is diagnosed against its "
                           "own library")
        out = _check_out(args.out)
        result = diagnose_order_domain(args.measured, cfg)
        doc = write_bode_outputs(result, out, args.command_line)
    else:
        from .gap.narx_view import narx_view_of

        base = paper_rotor_from_config(cfg)
        measured = load_measured(args.measured)
        if args.second_pass:
            try:
                kw_pass = {"second_pass": load_measured(args.second_pass)}
            except (ValueError, OSError) as exc:  # the file's fault: say which option
                raise ValueError(f"--second-pass {args.second_pass}: {exc}") from exc
        else:
            kw_pass = {}
        out = _check_out(args.out)
        start = time.perf_counter()

        def progress(msg):
            logger.info("[%6.1f s] %s", time.perf_counter() - start, msg)

        kw = {"candidates": tuple(args.candidates)} if args.candidates else {}
        if cfg.get("readings"):
            # the rotor file's alternative readings of its own model (docs/gap.md)
            kw["readings"] = cfg["readings"]
        if args.no_update:
            kw["update"] = False
        # each finished step is kept until the outputs are written: a stopped run
        # (Ctrl-C, a killed job) started again with the same options resumes
        kept = out / CHECKPOINT_DIR
        result = diagnose(measured, base=base, channels=args.channels, progress=progress,
                          checkpoint=kept, n_jobs=args.n_jobs, **kw, **kw_pass)
        narx = None
        if not args.no_narx and result["verdict"] != "no-gap":
            narx = narx_view_of(result, measured, base)
            progress("NARX view")
        doc = write_gap_outputs(result, out, args.command_line, narx)
        shutil.rmtree(kept, ignore_errors=True)
    print(_verdict_line(doc))
    print(f"wrote {out / 'report.html'} and {out / 'diagnosis.json'}")
    return 0


def _verdict_line(doc) -> str:
    """What ``sknarx gap`` prints: the verdict and its sentences, as the report states
    them (:func:`sknarx.gap.report_text.verdict_text`)."""
    from .gap.report_text import label, verdict_text

    return f"verdict: {label(doc['verdict'])}\n{verdict_text(doc)}"


def _unbalance(args) -> int:
    from .rotor.config import load_config
    from .unbalance import identify_unbalance, write_unbalance_outputs

    cfg = load_config(args.rotor)
    out = _check_out(args.out)
    doc = write_unbalance_outputs(identify_unbalance(args.features, cfg), out,
                                  args.command_line)
    cv = doc["cross_validation"]["methods"]["model-based (this package)"]
    print(f"leave-one-condition-out on {doc['cross_validation']['n_conditions']} labelled "
          f"conditions: MAE {cv['mae_gmm']:.2f} g mm, detection {100 * cv['detection']:.0f} %, "
          f"localisation {100 * cv['localisation']:.0f} %")
    print(f"wrote {out / 'predictions.csv'} ({len(doc['predictions'])} rows), "
          f"{out / 'report.html'} and {out / 'unbalance.json'}")
    return 0


def _datasets(args) -> int:
    from .datasets import DATASETS, dataset_path

    if args.action == "path":
        if not args.name:
            raise ValueError("sknarx datasets path NAME: give a dataset name, one of "
                             f"{', '.join(DATASETS)}.")
        print(dataset_path(args.name))
        return 0
    width = max(map(len, DATASETS))
    for name, (_, _, what) in DATASETS.items():
        print(f"{name:{width}s}  {what}")
    print("\n'sknarx datasets path NAME' prints a dataset's file; licence and provenance: "
          "sknarx.datasets' loaders (DESCR, license).")
    return 0


def _parser() -> argparse.ArgumentParser:
    from ._version import __version__

    common = argparse.ArgumentParser(add_help=False)
    talk = common.add_mutually_exclusive_group()
    talk.add_argument("-v", "--verbose", action="store_true",
                      help="say more about each step (debug-level log)")
    talk.add_argument("-q", "--quiet", action="store_true",
                      help="no progress bars or progress messages; warnings and the result "
                      "only")
    common.add_argument("--debug", action="store_true",
                        help="show the full traceback on an error")
    parser = _Parser(prog="sknarx", parents=[common],
                     description="Speed-scheduled NARX models of rotor-bearing systems, and "
                     "the sim-to-real gap of a rotor model.")
    parser.add_argument("--version", action="version", version=f"sknarx {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    p = sub.add_parser("paper", parents=[common],
                       help="reproduce Jin et al. 2022, Case 1, end to end")
    p.add_argument("--out", required=True, help="output folder (created)")
    p.add_argument("--n-jobs", type=int, default=2, help="parallel simulation workers")
    p.add_argument("--quick", action="store_true",
                   help="short records for a fast smoke run (not the paper's settings)")
    p.set_defaults(func=_paper)
    g = sub.add_parser("gap", parents=[common],
                       help="diagnose the sim-to-real gap of measured data")
    g.add_argument("--measured", required=True,
                   help="measured data: a .csv (comma or semicolon) or .parquet file")
    g.add_argument("--rotor", help="rotor description (.toml, .yaml or .json); default: "
                   "the paper's rotor")
    g.add_argument("--out", required=True,
                   help=f"output folder (created); a stopped run started again with the "
                   f"same options resumes from its {CHECKPOINT_DIR} folder")
    g.add_argument("--channels", nargs="+", choices=CHANNELS, metavar="CHANNEL",
                   help=f"channels to use (default: all DOF columns); from {', '.join(CHANNELS)}")
    g.add_argument("--candidates", nargs="+", choices=EFFECTS, metavar="EFFECT",
                   help=f"effects to search (default: all): {', '.join(EFFECTS)}")
    g.add_argument("--second-pass", metavar="FILE",
                   help="a second pass of the same sweep (e.g. the coast-down after the "
                        "run-up), same format: where it differs from --measured beyond the "
                        "noise, the rotor changed between the passes and the verdict is "
                        "unexplained")
    g.add_argument("--no-narx", action="store_true", help="skip the NARX view")
    g.add_argument("--n-jobs", type=int, default=None,
                   help="candidate fits run in parallel (default: one at a time, each "
                        "running its speed steps on every CPU)")
    g.add_argument("--no-update", action="store_true",
                   help="do not update the nominal rotor's parameters before blaming an "
                   "effect (only the four global nuisance scalars are fitted)")
    g.set_defaults(func=_gap)
    u = sub.add_parser("unbalance", parents=[common],
                       help="identify unbalance per disk from 1x response vectors through a "
                       "calibrated rotor model")
    u.add_argument("--features", required=True,
                   help="1x feature table (.csv or .parquet), one row per record, as "
                   "sknarx.datasets.load_rk4_unbalance")
    u.add_argument("--rotor", required=True,
                   help="rotor file (.toml) with a [[probes]] entry per probe of the table "
                   "and an [unbalance] section: the campaign's loaded_gmm, phase_from_gmm "
                   "and trial_runs (see examples/rk4/rotor.toml)")
    u.add_argument("--out", required=True, help="output folder (created)")
    u.set_defaults(func=_unbalance)
    d = sub.add_parser("datasets", parents=[common],
                       help="list the real measured data that ship with sknarx, or print "
                       "one's file path")
    d.add_argument("action", nargs="?", choices=("list", "path"), default="list",
                   help="list (default) or path NAME")
    d.add_argument("name", nargs="?", help="the dataset whose file path to print")
    d.set_defaults(func=_datasets, out=None)
    return parser


def _configure_logging(args) -> None:
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("sknarx: %(message)s"))
    logger.handlers = [h for h in logger.handlers if isinstance(h, logging.NullHandler)]
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False


def console_main() -> None:
    """The ``sknarx`` program: :func:`main` on ``sys.argv``, exiting with its code.

    After Ctrl-C the worker threads wind down before the interpreter exits; a second
    Ctrl-C then is ignored rather than shown as a traceback from that wind-down (the
    finished steps are already kept).
    """
    global _AS_PROGRAM
    _AS_PROGRAM = True
    sys.exit(main())


def main(argv=None) -> int:
    """Run the command line; returns the exit code (2 for a user error)."""
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    args = _parser().parse_args(argv)
    args.command_line = _command_line(argv)
    _configure_logging(args)
    # the commands parallelise over speed steps and candidates themselves: BLAS threads
    # of their small solves would only fight them for the cores (limited here and in
    # worker processes; the user's own environment setting wins there)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _run(args)


def _run(args) -> int:
    try:
        return args.func(args)
    except KeyboardInterrupt:
        if _AS_PROGRAM and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C: see console_main
        kept = Path(args.out) / CHECKPOINT_DIR if args.command == "gap" else None
        print("sknarx: interrupted" + (
            f"; the same command again resumes from {kept}" if kept and kept.exists()
            else ""), file=sys.stderr)
        return 130
    except (ValueError, OSError, ImportError) as exc:
        # the library validates user input with these, and says what to fix
        if args.debug:
            raise
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"sknarx {args.command}: error: {message}", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug: say so, keep the traceback behind --debug
        if args.debug:
            raise
        message = " ".join(str(exc).split())
        print(f"sknarx {args.command}: internal error ({type(exc).__name__}: {message}); "
              "rerun with --debug for the traceback and please report it", file=sys.stderr)
        return 1


if __name__ == "__main__":
    console_main()
