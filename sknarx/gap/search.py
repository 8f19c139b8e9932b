"""Which candidates are fitted: singles, the lead continued, pairs, linear forms, settings.

A measurement front end (time-series sweeps in :mod:`sknarx.gap.timeseries`,
order-tracked Bode records in :mod:`sknarx.bode.diagnosis`) owns its model and fits
each candidate on the training part of the record through the :class:`FrontEnd` hooks;
the search here decides which candidates and pairs are fitted, the same way for both,
and ranks them by held-out excess plus two per added parameter (an AIC on the
chi-square scale).
"""

from __future__ import annotations

import logging

import pandas as pd
from joblib import Parallel, delayed

from .._progress import phase, progress_bar
from .candidate import Candidate
from .evidence import log_shrink

__all__ = ["FrontEnd", "rank", "search", "recheck_setting", "run_parallel"]

logger = logging.getLogger(__name__)


class FrontEnd:
    """What :func:`search` asks of a measurement front end.

    ``fit`` and ``fit_pair`` are required; the other hooks default to the plain search
    (no continued lead, every other candidate a partner, no member refits, no linear
    forms, no discrete settings). Hooks may run in other processes (joblib backends):
    what a fit learns travels in the :class:`~sknarx.gap.candidate.Candidate` it
    returns, and :meth:`absorb` hands it back to the front end in the caller.
    """

    def fit(self, names: tuple) -> Candidate:
        """Calibrate the candidate ``names`` (one effect) on the training part."""
        raise NotImplementedError

    def fit_pair(self, lead: Candidate, partner: str) -> Candidate:
        """Calibrate the lead with ``partner``."""
        raise NotImplementedError

    def absorb(self, fit: Candidate) -> None:
        """Keep what a fit made elsewhere learned (each discrete setting's fit)."""

    def continue_fit(self, fit: Candidate) -> Candidate | None:
        """A further run of the leading single from its own fit (None: not offered)."""
        return None

    def partners(self, lead: Candidate, others: list, k: int, n_jobs=None) -> list:
        """Up to ``k`` candidates worth pairing with the lead, most promising first."""
        return list(others)[:k]

    def refit_members(self, pair: Candidate) -> list:
        """Each member of the best pair alone, started from the pair's fit."""
        return []

    def linear_forms(self, fit: Candidate) -> list:
        """The candidate refitted with each member that has a linear form
        (:attr:`sknarx.rotor.Effect.linear_form`) in that form: named by its other
        members, the linear form's fit in ``details["model_error"]``."""
        return []

    def recheck_setting(self, fit: Candidate) -> tuple | None:
        """Each other discrete setting of ``fit`` refitted from its fit: the fit's
        setting entries (``discrete_settings``, ``setting_decided``) and the fit of a
        setting that did better (else None); None: nothing to recheck."""
        return None


def run_parallel(n_jobs, calls, desc):
    """``calls`` (zero-argument callables) through joblib with a progress bar; results in
    submission order. The backend is the caller's (``joblib.parallel_config``): a
    dask.distributed cluster runs them there."""
    calls = list(calls)
    if not calls:
        return []
    gen = Parallel(n_jobs=n_jobs, return_as="generator")(delayed(c)() for c in calls)
    return list(progress_bar(gen, total=len(calls), desc=desc, unit="fit"))


def rank(fits: list, E0: float, cmp0: pd.DataFrame) -> list:
    """``fits`` best first by held-out excess plus two per added parameter, each with
    the gap before any candidate (``heldout_before``) and the breadth of its gain
    (``log_shrink``) set."""
    for f in fits:
        f.heldout_before = float(E0)
        f.log_shrink = log_shrink(cmp0, f.cmp)
    return sorted(fits, key=lambda f: f.score)


def search(front: FrontEnd, candidates, E0: float, cmp0: pd.DataFrame, n_features: int,
           rule, budget, n_jobs=None, tick=None) -> list:
    """Fit every candidate, then pairs where the best single leaves a gap; the ranking.

    1. Every candidate alone (``front.fit``).
    2. The leading single continued from its own fit (``front.continue_fit``), whether
       or not pairs follow: a pair is warm-started from the lead's fit, and the lead
       gets the same chance, so a partner is not credited with the lead's convergence.
    3. Where the lead leaves more than ``budget.pair_search_from`` (or the rule's
       ``pair_trigger``, the smaller) held-out excess per feature: the lead with each of
       up to ``budget.n_partners`` partners; each member of the best pair is then
       refitted alone from it and replaces its single fit where it does better.
    4. Effect or model error (:func:`_without_linear_members`).
    """
    tick = tick or (lambda msg: None)
    singles = run_parallel(n_jobs, [lambda c=c: front.fit((c,)) for c in candidates],
                           "effect candidates")
    for f in singles:
        front.absorb(f)
    tick("single candidates")
    ranked = rank(singles, E0, cmp0)
    if not ranked:
        return ranked
    lead = ranked[0]
    with phase("continuing " + "+".join(lead.effects)):
        more = front.continue_fit(lead)
    if more is not None:
        if more.heldout_after < lead.heldout_after:
            singles = [more if f is lead else f for f in singles]
            lead = rank(singles, E0, cmp0)[0]
        tick("lead continued")
    pairs = []
    if lead.heldout_after / max(n_features, 1) > min(rule.pair_trigger,
                                                      budget.pair_search_from):
        others = [c for c in candidates if (c,) != lead.effects]
        with phase("choosing partners of " + "+".join(lead.effects)):
            partners = front.partners(lead, others, budget.n_partners, n_jobs)
        pairs = run_parallel(n_jobs, [lambda p=p: front.fit_pair(lead, p) for p in partners],
                             "pairs")
        for f in pairs:
            front.absorb(f)
        if pairs:
            top = rank(pairs, E0, cmp0)[0]
            for new in front.refit_members(top):
                singles = [new if f.effects == new.effects
                           and new.heldout_after < f.heldout_after else f for f in singles]
        tick("pairs")
    return _without_linear_members(front, singles + pairs, E0, cmp0, rule, tick)


def _contenders(ranked: list) -> list:
    """The best single (model error alone counts as one) and the best pair of a
    ranking: whatever its values, the rule chooses between these two."""
    out = []
    for keep in (lambda n: n <= 1, lambda n: n == 2):
        group = [c for c in ranked if keep(len(c.effects))]
        if group:
            out.append(min(group, key=lambda c: c.score))
    return out


def _without_linear_members(front, fits, E0, cmp0, rule, tick) -> list:
    """Step 4 of :func:`search`: each member with a linear form (an anisotropy's is the
    isotropic support) of the two contenders is refitted in that form. Where the form
    scores as well (held-out excess plus two per parameter: the restriction costs at
    most the parameter it saves), the member changed the linear rotor only -- model
    error by the rule that separates the two -- and the candidate gives way to its
    other members with the model error stated (none left: model error alone); the
    replacement says what it replaced (``replaces``), a member that passed says so
    (``linear_form_tests``). A candidate that beats its form by less than the rule's
    ``min_gain`` is out of the verdict, so the next contenders are tested in turn."""
    ranked = rank(fits, E0, cmp0)
    tested = set()
    while todo := [c for c in _contenders([c for c in ranked
                                           if not rule.beyond_linear_form(c)])
                   if c.effects and c.effects not in tested]:
        fit = todo[0]
        tested.add(fit.effects)
        with phase("linear form of " + "+".join(fit.effects)):
            alts = front.linear_forms(fit)
        if not alts:
            continue
        tick("effect or model error: " + "+".join(fit.effects))
        for alt in alts:
            member = ", ".join(n for n in fit.effects if n not in alt.effects)
            form = ", ".join(alt.details["model_error"])
            score = alt.heldout_after + 2.0 * alt.n_params
            if score > fit.score:
                fit.details.setdefault("linear_form_tests", []).append(
                    {"member": member, "linear_form": form,
                     "heldout_gap_after": alt.heldout_after, "score": score,
                     "outcome": "effect"})
                continue
            logger.info("%s: the %s did no more than %s (held-out excess %.4g against "
                        "%.4g): model error, not an effect", "+".join(fit.effects), member,
                        form, alt.heldout_after, fit.heldout_after)
            alt.details["replaces"] = {"effect": list(fit.effects), "member": member,
                                       "heldout_gap_after": fit.heldout_after,
                                       "score": fit.score}
            fits = [f for f in fits if f is not fit
                    and not (f.effects == alt.effects
                             and f.heldout_after >= alt.heldout_after)]
            fits.append(alt)
            break
        ranked = rank(fits, E0, cmp0)
    return ranked


def recheck_setting(front: FrontEnd, verdict, ranking: list, E0: float, cmp0, rule,
                    n_features: int, floor):
    """Where the named candidate has a discrete setting (a crack's station, a rub's
    disk), each other setting refitted from its fit (``front.recheck_setting``): a
    setting whose own search missed the basin the chosen one found is no evidence
    against it, and one that now fits the held-out speeds better replaces the fit in
    the ranking, which is then decided again (once). Returns the verdict and ranking."""
    fit = verdict.named
    if fit is None or not fit.details.get("discrete_settings"):
        return verdict, ranking
    with phase("other settings of " + "+".join(fit.effects)):
        out = front.recheck_setting(fit)
    if not out:
        return verdict, ranking
    entries, better = out
    if better is None:
        fit.details.update(entries)
        return verdict, ranking
    better.details.update(entries)
    ranking = rank([better if f is fit else f for f in ranking], E0, cmp0)
    return rule.decide(verdict.e0, ranking, floor, n_features), ranking
