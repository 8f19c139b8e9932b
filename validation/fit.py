"""Fit the verdict rule's tuned values on pilot trials: ``python -m validation.fit RUN``.

The four values of :class:`~sknarx.gap.VerdictRule` that are not stated or measured --
``min_shrink``, ``min_log_shrink``, ``pair_trigger`` and ``min_gain`` -- are chosen on
pilot trials of the own family (``python -m validation.run --families own ...``), never
on the trials that score them: a grid search maximises the worst of top-1, one minus
the false-alarm rate and the out-of-library ``unexplained`` rate (their mean breaks
near-ties); among settings that tie, each value takes the median of its tied values,
away from the edges of the tie. The rule's other values are stated
(``false_alarm``, ``rtol``, ``line_sigmas``, ``keyphasor_deg``, ``speed_rtol``) or
measured (``harmonic_rtol``), not fitted.
"""

from __future__ import annotations

import argparse
import itertools
from dataclasses import replace

import numpy as np

from sknarx.gap import VerdictRule

from .score import rates, read_run

__all__ = ["GRID", "objective", "fit_rule"]

#: the values searched
GRID = {"min_shrink": (0.5, 0.6, 0.7, 0.8),
        "min_log_shrink": (0.0, 0.3, 0.5, 0.6, 0.7),
        "pair_trigger": (0.5, 1.0, 2.0),
        "min_gain": (0.3, 0.5, 0.7)}


def objective(records, rule: VerdictRule) -> float:
    """The worst of top-1, one minus false alarms and out-of-library ``unexplained`` on
    ``records`` under ``rule``, plus a thousandth of their mean."""
    r = rates(records, rule)

    def share(k_n, flip=False):
        k, n = k_n
        if not n:
            return np.nan
        return 1.0 - k / n if flip else k / n

    vals = [share(r["top1"]), share(r["false_alarm"], flip=True),
            share(r["unexplained_out_of_library"])]
    return float(np.nanmin(vals) + 1e-3 * np.nanmean(vals))


def fit_rule(records, base: VerdictRule | None = None, grid=GRID) -> VerdictRule:
    """The rule with the grid's values that maximise :func:`objective` on ``records``."""
    base = base or VerdictRule()
    names = list(grid)
    scored = [(objective(records, replace(base, **dict(zip(names, combo, strict=True)))),
               combo) for combo in itertools.product(*grid.values())]
    top = max(v for v, _ in scored)
    tied = [c for v, c in scored if v >= top - 1e-12]
    middle = tuple(sorted(col)[(len(col) - 1) // 2] for col in zip(*tied, strict=True))
    pick = middle if middle in tied else tied[0]
    return replace(base, **dict(zip(names, pick, strict=True)))


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m validation.fit",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="run folders holding own.jsonl.gz pilot logs")
    args = ap.parse_args(argv)
    records = [r for run in args.runs for r in read_run(run).get("own", [])]
    if not records:
        ap.error("no own-family pilot trials in " + ", ".join(args.runs))
    fitted = fit_rule(records)
    frozen = VerdictRule()
    print(f"{len(records)} pilot trials")
    for name in GRID:
        print(f"{name:16s} fitted {getattr(fitted, name):<6g} frozen {getattr(frozen, name):g}")
    print(f"objective: fitted {objective(records, fitted):.4f}, "
          f"frozen {objective(records, frozen):.4f}")
    return fitted


if __name__ == "__main__":
    main()
