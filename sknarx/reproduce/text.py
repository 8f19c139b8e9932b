"""The sentences of the paper report, each made from the values and the rule that
decide it.

A sentence that draws a conclusion ("well determined", "does not meet the targets",
"cuts the error") states the rule it applies and has a branch for each outcome, so the
report cannot say one thing beside a number that says another.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.stats import norm

from .._report import percentage, quantity

__all__ = ["Z95", "coefficient_text", "acceptance_text", "targets_text", "change_text",
           "harmonics_text", "aerr_text"]

#: the normal deviate of a two-sided 95 % interval: a coefficient whose relative standard
#: error exceeds 1 / Z95 (51 %) has an interval that includes zero
Z95 = float(norm.ppf(0.975))


def _pct(share, digits=3) -> str:
    return "-" if share is None or not np.isfinite(share) else f"{100 * share:.{digits}g} %"


def coefficient_text(summary: pd.DataFrame, model_name: str) -> str:
    """Whether the data determine the coefficients, by their 95 % intervals.

    ``summary``: :meth:`~sknarx.SpeedScheduledNarx.summary` (``term``, ``speed``,
    ``coef``, ``std_err``)."""
    rel = (summary["std_err"] / summary["coef"]).abs().replace(np.inf, np.nan)
    ok = rel.notna()
    if not ok.any():
        return (f"No standard error of the {model_name} model's coefficients could be "
                "estimated (too few samples per speed for its terms).")
    n, worst = int(ok.sum()), rel[ok].idxmax()
    w = summary.loc[worst]
    largest = (f"largest relative standard error {_pct(rel[worst])}, {w.term} at "
               f"{quantity(w.speed, 'rad/s')}")
    loose = rel[ok] > 1.0 / Z95
    if not loose.any():
        return (f"Every coefficient of the {model_name} model at every speed ({n} in all) "
                f"has a 95 % interval that excludes zero ({largest}): the data determine "
                "them, and what limits the model is its structure, which the validation "
                "below measures.")
    terms = summary.loc[loose[loose].index, "term"].value_counts()
    by_term = ", ".join(f"{t} at {k} speed(s)" for t, k in terms.items())
    return (f"{int(loose.sum())} of the {n} coefficients of the {model_name} model (one per "
            f"term and speed) have a 95 % interval that includes zero, a relative standard "
            f"error above {_pct(1 / Z95, 2)} ({largest}): {by_term}. There the data do not "
            "determine the coefficient; the speed functions through them carry that "
            "uncertainty (the bands of the coefficient figure).")


def acceptance_text(passed: list[bool], pooled: pd.DataFrame, model_name: str) -> str:
    """How the acceptance points and the residual correlation tests fit together.

    ``passed``: each acceptance point's outcome; ``pooled``: the model's pooled rows of
    :func:`~sknarx.narx.validity.validity_summary` (``test``, ``passed``)."""
    n, n_ok = len(passed), int(sum(passed))
    head = (f"All {n} acceptance points pass" if n_ok == n else
            f"{n - n_ok} of the {n} acceptance points fail")
    failed = list(pooled.loc[~pooled["passed"].astype(bool), "test"])
    if not failed:
        return (f"{head}, and the {model_name} model's one-step residuals pass all "
                f"{len(pooled)} correlation tests pooled over the speeds: nothing in them is "
                "left for the term set to predict.")
    why = ("accurate enough for the paper's targets, not structurally complete" if n_ok == n
           else "short of the paper's targets and not structurally complete")
    return (f"{head}. They judge the free run against the paper's targets; the residual "
            "correlation tests (<i>Judging the models</i>) ask whether the one-step "
            f"residuals hold anything the model could still predict, and pooled over the "
            f"speeds the {model_name} model fails {len(failed)} of {len(pooled)} "
            f"({', '.join(failed)}). On noise-free simulation a failing test means a "
            f"truncated term set: the model is {why}.")


def targets_text(rows: pd.DataFrame, limits: dict) -> str:
    """Whether a model's validation rows (``nrmse``, ``amp1x_rel_error``) meet the
    limits, with the values."""
    nrmse = ", ".join(_pct(x) for x in rows["nrmse"])
    one_x = ", ".join(_pct(x) for x in rows["amp1x_rel_error"])
    meets = bool(((rows["nrmse"] <= limits["nrmse"])
                  & (rows["amp1x_rel_error"] <= limits["amp1x_rel_error"])).all())
    verb = "meets" if meets else "does <b>not</b> meet"
    return (f"{verb} the validation targets (steady NRMSE {nrmse} against at most "
            f"{_pct(limits['nrmse'])}; 1x amplitude error {one_x} against at most "
            f"{_pct(limits['amp1x_rel_error'])})")


def change_text(what: str, new: float, old: float, old_name: str) -> str:
    """``what`` after a change against before it (``old_name``), with the verb the
    values give: lower is better."""
    if not (np.isfinite(new) and np.isfinite(old)):
        return f"{what} is {_pct(new)} ({old_name}: {_pct(old)})"
    if new < old:
        return f"cuts {what} to {_pct(new)} ({old_name}: {_pct(old)})"
    if new == old:
        return f"leaves {what} at {_pct(new)} ({old_name}: the same)"
    return f"does not cut {what}: {_pct(new)} against {_pct(old)} ({old_name})"


def harmonics_text(runs: dict, disk: str = "xO1", journal: str = "xA") -> str:
    """The 2x against the 1x at the disk and at a journal, over the figure speeds.

    ``runs``: speed (rad/s) -> a simulated record (``phi`` and the DOF columns)."""
    from ..orders import order_components

    ratios = {disk: [], journal: []}
    for run in runs.values():
        half = slice(len(run) // 2, None)
        phi = run["phi"].to_numpy()[half]
        for dof in ratios:
            a = order_components(run[dof].to_numpy()[half], phi, (1, 2))[0]
            ratios[dof].append(a[1] / a[0] if a[0] > 0 else np.nan)
    d, j = (np.asarray(ratios[k]) for k in (disk, journal))
    if not (np.isfinite(d).any() and np.isfinite(j).any()):
        return ""

    def span(r):
        lo, hi = np.nanmin(r), np.nanmax(r)
        return f"{lo:.1e}" if np.isclose(lo, hi, rtol=0.05) else f"{lo:.1e} to {hi:.1e}"

    where = ("relatively stronger at the journal" if np.nanmedian(j) > np.nanmedian(d)
             else "relatively stronger at the disk")
    dominant = bool(np.nanmax(np.concatenate([d, j])) < 1.0)
    lead = "1x dominates at every figure speed" if dominant else "1x does not dominate everywhere"
    speeds = ", ".join(f"{w:g}" for w in runs)
    return (f"{lead} ({speeds} rad/s): the 2x component is {span(d)} of the 1x at the disk "
            f"({disk}) and {span(j)} at the journal ({journal}), {where} (the 2x comes from "
            "the gravity-preloaded Hertzian bearings).")


def aerr_text(total_percent: float) -> str:
    """The total AERR, never rounded up to 100 % when short of it."""
    return percentage(total_percent, 6)
