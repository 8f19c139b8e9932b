"""The gap core both measurement front ends share: split, search, rank, decide, shrink.

A front end (time-series sweeps in :mod:`sknarx.gap.diagnosis`, order-tracked Bode
records in :mod:`sknarx.gap.orderdomain`) owns its model: it calibrates the nominal
model and fits each candidate effect on the training part of the record, and returns
the held-out comparison table of each fit (one row per held-out feature: ``speed`` in
rad/s, ``window``, ``channel``, ``feature``, ``gap`` in m, ``z2`` and ``excess``, see
:func:`sknarx.gap.compare`). Everything after that is decided here, the same way for
both:

* the split into training and held-out speeds (:func:`alternating_split`);
* which candidates and pairs are fitted (:func:`search`, through the front end's
  :class:`FrontEnd` hooks);
* the ranking by held-out excess plus two per effect parameter, an AIC on the
  chi-square scale (:func:`rank`);
* the verdict (:func:`decide`, thresholds from the front end's
  :class:`~sknarx.gap.DiagnosisSettings`), with the held-out 1x, 2x and 3x features
  also tested order by order (:func:`orders_over_floor`);
* how firmly the held-out speeds chose a discrete setting (a crack's station, a rub's
  disk) over the others (:func:`setting_support`);
* the shrink of the held-out gap with its bootstrap band over held-out speeds
  (:func:`bootstrap_shrink`) and where the gap was and what remains of it
  (:func:`~sknarx.gap.regions`, :func:`regions_after`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd
from joblib import Parallel, delayed

from .._progress import progress_bar

__all__ = ["CandidateFit", "FrontEnd", "alternating_split", "bootstrap_shrink", "closest",
           "conclude", "decide", "effect_names", "log_shrink", "order_floors",
           "order_mean_z2", "orders_over_floor",
           "pair_search_from", "pair_under_trigger", "preferred", "public_ranking", "rank",
           "recheck_choice", "regions_after",
           "judged_shrink", "run_parallel", "search", "setting_support", "shortfalls", "shrink",
           "table_evidence", "with_passes"]

logger = logging.getLogger(__name__)

_KEY = ["speed", "window", "channel", "feature"]

#: the orders whose held-out features are tested on their own beside the mean over every
#: feature, in the order of :attr:`~sknarx.gap.DiagnosisSettings.order_floors_z2`
TESTED_ORDERS = ("1x", "2x", "3x")


def alternating_split(n: int, block: int = 1) -> np.ndarray:
    """Training mask of ``n`` speed-ordered units: alternating blocks of ``block`` units,
    the first for training, and the last unit always for training. The held-out units lie
    between training ones, so a fit is judged where it interpolates, never where it
    extrapolates (with an even count of single steps the plain alternation held out the
    top speed, above every training one).

    Examples
    --------
    >>> alternating_split(6).astype(int).tolist()
    [1, 0, 1, 0, 1, 1]
    >>> alternating_split(7, block=2).astype(int).tolist()
    [1, 1, 0, 0, 1, 1, 1]
    """
    train = (np.arange(n) // block) % 2 == 0
    if n:
        train[-1] = True
    return train


def shrink(before: float, after: float) -> float:
    """Share of a held-out excess removed (0 when there was none)."""
    return float(1.0 - after / before) if before > 0 else 0.0


def log_shrink(cmp_before: pd.DataFrame, cmp_after: pd.DataFrame | None) -> float:
    """Share of ``sum(log(1 + excess))`` removed: the breadth of a fit's gain (the
    excess is dominated by its largest features; this is not)."""
    if cmp_after is None:
        return -np.inf
    b = cmp_before.set_index(_KEY)["excess"]
    a = cmp_after.set_index(_KEY)["excess"].reindex(b.index).fillna(0.0)
    lb = np.log1p(b).sum()
    return float(1.0 - np.log1p(a).sum() / lb) if lb > 0 else 0.0


def bootstrap_shrink(cmp_before: pd.DataFrame, cmp_after: pd.DataFrame, n: int,
                     seed: int) -> list[float]:
    """5-95 % band of the shrink, resampling held-out speeds with replacement."""
    rng = np.random.default_rng(seed)
    b = cmp_before.groupby("speed")["excess"].sum()
    a = cmp_after.groupby("speed")["excess"].sum().reindex(b.index).fillna(0.0)
    vb, va = b.to_numpy(), a.to_numpy()
    vals = []
    for _ in range(n):
        pick = rng.choice(len(vb), len(vb), replace=True)
        vals.append(shrink(vb[pick].sum(), va[pick].sum()))
    return [float(np.percentile(vals, 5)), float(np.percentile(vals, 95))]


def setting_support(cmp_chosen: pd.DataFrame, cmp_other: pd.DataFrame | None, n: int,
                    seed: int) -> float:
    """Share of bootstrap resamples of the held-out speeds in which ``cmp_chosen``
    leaves less held-out excess than ``cmp_other`` (ties count half; a diverged other,
    None, is beaten every time).

    The two tables are paired speed by speed, so what they share (the noise, the
    model-form mismatch both carry) cancels: 0.5 is "the held-out speeds do not tell
    them apart", 1.0 "every resample prefers the chosen one".

    Examples
    --------
    >>> import pandas as pd
    >>> a = pd.DataFrame({"speed": [1.0, 2.0, 3.0], "excess": [0.0, 1.0, 0.0]})
    >>> setting_support(a, a, 100, 0)
    0.5
    >>> setting_support(a, a.assign(excess=a.excess + 1.0), 100, 0)
    1.0
    """
    if cmp_other is None:
        return 1.0
    a = cmp_chosen.groupby("speed")["excess"].sum()
    b = cmp_other.groupby("speed")["excess"].sum().reindex(a.index).fillna(0.0)
    diff = (b - a).to_numpy()  # > 0 where the chosen setting leaves less
    if diff.size == 0:
        return 0.5
    rng = np.random.default_rng(seed)
    sums = diff[rng.integers(0, diff.size, size=(n, diff.size))].sum(axis=1)
    return float(np.mean(sums > 0) + 0.5 * np.mean(sums == 0))


def table_evidence(cmp_before: pd.DataFrame, cmp_after: pd.DataFrame, k: int = 3) -> list:
    """The features whose gap a fit removed most (its signature evidence), as text."""
    key = ["channel", "feature", "window"]
    b = cmp_before.groupby(key)["excess"].sum()
    a = cmp_after.groupby(key)["excess"].sum().reindex(b.index).fillna(0.0)
    gain = (b - a).sort_values(ascending=False)
    total = b.sum()
    out = []
    for (ch, feat, win), g in gain.head(k).items():
        if g <= 0:
            break
        out.append(f"{feat} at {ch} ({win}): {100 * g / total:.0f} % of the gap removed")
    return out


def regions_after(where: list, cmp_after: pd.DataFrame, cmp_before: pd.DataFrame) -> list:
    """Each gap region with its held-out excess before and after the verdict."""
    def select(c, r):
        lo, hi = r["speed_range"]
        return c[(c.channel == r["channel"]) & (c.feature == r["order"])
                 & (c.window == r["window"]) & (c.speed >= lo) & (c.speed <= hi)]

    return [{**r, "heldout_excess_before": float(select(cmp_before, r)["excess"].sum()),
             "heldout_excess_after": float(select(cmp_after, r)["excess"].sum())}
            for r in where]


@dataclass
class CandidateFit:
    """One candidate (a single effect or a pair) fitted by a front end.

    ``n_params`` counts the parameters the candidate adds to the calibrated nominal
    model (the AIC's penalty); ``heldout_excess`` and ``cmp`` are its held-out excess
    and comparison table (``inf`` and None when the fitted model diverged at a held-out
    speed); ``details`` are front-end entries for the ranking (nuisances, evidence,
    fitted unbalance, ...); ``state`` is the front end's own fit, for warm starts.
    """

    names: tuple
    params: Any
    params_std: dict
    n_params: int
    heldout_excess: float
    cmp: pd.DataFrame | None
    details: dict = field(default_factory=dict)
    state: Any = None


def effect_names(entry: dict) -> tuple:
    """The effect names of a ranking entry (one, or the two of a pair)."""
    e = entry["effect"]
    return (e,) if isinstance(e, str) else tuple(e)


def rank(fits: list, E0: float, cmp0: pd.DataFrame) -> list[dict]:
    """Ranking entries of fitted candidates, best first: held-out excess after plus two
    per added parameter. ``_cmp`` and ``_fit`` (the held-out table and the fit) are for
    the core and the reports, not the document. A candidate whose only change is to the
    linear rotor (no effect left, see :func:`search`) has ``effect`` ``[]``."""
    out = []
    for f in fits:
        E = f.heldout_excess
        out.append({
            "effect": f.names[0] if len(f.names) == 1 else list(f.names),
            "params": f.params, "params_std": f.params_std,
            "heldout_gap_before": E0, "heldout_gap_after": E, "shrink": shrink(E0, E),
            "log_shrink": log_shrink(cmp0, f.cmp), "score": E + 2.0 * f.n_params,
            **f.details, "_cmp": f.cmp, "_fit": f,
        })
    out.sort(key=lambda r: r["score"])
    return out


def pair_search_from(settings) -> float:
    """The excess per feature above which the best single gets partners: pairs are
    searched from ``pair_search_trigger`` and named only above ``pair_trigger``, and a
    pair that is not searched cannot be named, so the smaller of the two."""
    return min(settings.pair_trigger, settings.pair_search_trigger)


def preferred(ranking: list, settings, n_features: int):
    """The best single candidate, or the best pair where it earns its place: the single
    leaves more than ``pair_trigger`` excess per feature, the pair removes
    ``pair_gain`` of what the single leaves, (with ``pair_margin`` set) scores at
    least that much below it and (with ``pair_rival_shrink`` set) its members are not
    rivals (:func:`rivals`). A candidate whose member does too little more than its
    linear form (:func:`beats_linear_form`) is left out. None without any single."""
    # a candidate left with model error only competes as a single would
    ranking = [r for r in ranking if beats_linear_form(r, settings.linear_form_gain)]
    singles = [r for r in ranking if len(effect_names(r)) <= 1]
    pairs = [r for r in ranking if len(effect_names(r)) == 2]
    if not singles:
        return None
    best = min(singles, key=lambda r: r["score"])
    left = best["heldout_gap_after"]
    if pairs and left / n_features > settings.pair_trigger:
        pb = min(pairs, key=lambda r: r["score"])
        margin = settings.pair_margin
        if (pb["heldout_gap_after"] <= (1.0 - settings.pair_gain) * left
                and (margin is None or best["score"] - pb["score"] >= margin)
                and not rivals(pb, singles, settings.pair_rival_shrink, settings,
                               n_features)):
            return pb
    return best


def beats_linear_form(entry: dict, gain: float | None) -> bool:
    """Whether each member of ``entry`` that was tested against its linear form
    (``linear_form_tests``, see :func:`search`) removes at least ``gain`` of the held-out
    excess that form leaves. The search keeps a member as an effect whenever it scores
    better than its form; with the held-out excess dominated by model-form error on a
    rotor the model does not describe exactly, a member's extra parameters always buy
    some of it -- an anisotropy whose two directions differ by little takes the share of
    an isotropic support's (a pedestal's mass and stiffness the nominal model lacks) and
    beats that form by a few per cent. ``gain`` None, or no member tested: True."""
    return all(passes_form_test(entry, t, gain) for t in entry.get("linear_form_tests", ()))


def passes_form_test(entry: dict, test: dict, gain: float | None) -> bool:
    """Whether ``entry`` removes at least ``gain`` of what one member's linear form
    leaves (``test``, one of its ``linear_form_tests``); ``gain`` None: True."""
    return gain is None or removed_beyond_form(entry, test) >= gain


def removed_beyond_form(entry: dict, test: dict) -> float:
    """The share of the held-out excess a member's linear form leaves (``test``, one of
    ``entry``'s ``linear_form_tests``) that ``entry`` removes; 0 where the form leaves
    none."""
    left = test["heldout_gap_after"]
    return 1.0 - entry["heldout_gap_after"] / left if left > 0 else 0.0


def rival_pair_set_aside(ranking: list, settings, n_features: int) -> dict | None:
    """The ranking's entry for the pair :func:`preferred` would have named but for the
    rival test (``settings.pair_rival_shrink``), with what each member removes alone
    (``members_alone``); None where the test changed nothing."""
    if settings.pair_rival_shrink is None:
        return None
    plain = preferred(ranking, replace(settings, pair_rival_shrink=None), n_features)
    if (plain is None or len(effect_names(plain)) != 2
            or preferred(ranking, settings, n_features) is plain):
        return None
    alone = shrinks_alone(ranking, settings, n_features)
    return {"effect": plain["effect"], "shrink": plain["shrink"],
            "heldout_gap_after": plain["heldout_gap_after"],
            "members_alone": {name: alone[name] for name in effect_names(plain)},
            "pair_rival_shrink": settings.pair_rival_shrink}


def pair_under_trigger(ranking: list, settings, n_features: int) -> dict | None:
    """The ranking's entry for the pair :func:`preferred` would have chosen but for the
    pair trigger: pairs are searched from ``pair_search_trigger``, and a pair found
    where the best single leaves no more than ``pair_trigger`` per feature is ranked,
    not named. With it the single (``single``), what the single leaves per feature
    (``single_leaves_per_feature``), the share of that the pair removes
    (``removes_of_single``) and the trigger; None where the trigger changed nothing."""
    plain = preferred(ranking, replace(settings, pair_trigger=0.0), n_features)
    # preferred names the best pair or the best single: not the pair, so the single
    best = preferred(ranking, settings, n_features)
    if plain is None or len(effect_names(plain)) != 2 or best is plain:
        return None
    left = best["heldout_gap_after"]
    return {"effect": plain["effect"], "shrink": plain["shrink"],
            "heldout_gap_after": plain["heldout_gap_after"], "single": best["effect"],
            "single_leaves_per_feature": left / n_features,
            "removes_of_single": 1.0 - plain["heldout_gap_after"] / left if left > 0 else 0.0,
            "pair_trigger": settings.pair_trigger}


def shrinks_alone(ranking: list, settings=None, n_features: int = 1) -> dict[str, float]:
    """The share of the held-out gap each effect fitted alone removes (its single entry
    in ``ranking``), by name: as the verdict judges it (:func:`judged_shrink`) with
    ``settings``, the plain shrink without. An effect fitted alone more than once (with
    rotor readings: on the rotor as given and in a reading) counts its best fit: what it
    can remove alone."""
    alone: dict[str, float] = {}
    for r in ranking:
        names = effect_names(r)
        if len(names) == 1:
            share = r["shrink"] if settings is None else judged_shrink(r, settings, n_features)
            alone[names[0]] = max(alone.get(names[0], -np.inf), share)
    return alone


def rivals(pair: dict, singles: list, share: float | None, settings=None,
           n_features: int = 1) -> bool:
    """Whether each member of ``pair``, fitted alone (its entry among ``singles``),
    removes at least ``share`` of the held-out gap (as :func:`shrinks_alone` measures it
    with ``settings``): two rival readings of one signature, not two effects (see
    ``DiagnosisSettings.pair_rival_shrink``). A member not fitted alone is no rival;
    ``share`` None: never."""
    if share is None:
        return False
    alone = shrinks_alone(singles, settings, n_features)
    return all(alone.get(name, -np.inf) >= share for name in effect_names(pair))


def judged_shrink(entry: dict, settings, n_features: int) -> float:
    """The share of the held-out gap a ranking ``entry`` removes, as the verdict judges
    it: of the excess above the effect-free noise, ``(E0 - E) / (E0 - n m0)`` with ``m0``
    ``settings.noise_per_feature`` and ``n`` the held-out features. No candidate removes
    the noise, and near the no-gap floor it is a third of ``E0``, so the plain share
    ``(E0 - E) / E0`` would ask a mild effect to remove some of it too. The plain share
    where ``m0`` is None, the gap is not above the noise, or the entry does not carry its
    gap before (``heldout_gap_before``)."""
    m0 = settings.noise_per_feature
    E0 = entry.get("heldout_gap_before")
    above = E0 - m0 * n_features if m0 is not None and E0 is not None else 0.0
    if above <= 0:
        return entry["shrink"]
    return (E0 - entry["heldout_gap_after"]) / above


def order_mean_z2(cmp: pd.DataFrame) -> dict[str, dict]:
    """Each :data:`TESTED_ORDERS` order's mean z2 over its held-out features in the
    comparison table ``cmp``, with their number: ``{order: {"mean_z2", "n"}}`` (orders
    the table lacks are left out)."""
    rows = cmp[cmp["feature"].isin(TESTED_ORDERS)].groupby("feature")["z2"]
    return {k: {"mean_z2": float(m), "n": int(n)}
            for k, m, n in zip(rows.mean().index, rows.mean(), rows.size(), strict=True)}


def order_floors(settings) -> dict[str, float]:
    """Each :data:`TESTED_ORDERS` order's floor from ``settings.order_floors_z2``
    (order to mean z2; empty with the floors unset)."""
    floors = settings.order_floors_z2
    return {} if floors is None else dict(zip(TESTED_ORDERS, floors, strict=True))


def orders_over_floor(mean_z2: dict, settings) -> dict[str, float]:
    """The orders whose mean z2 over their held-out features (``mean_z2``: order to
    value) exceeds that order's floor in ``settings.order_floors_z2``, with the value.

    The held-out excess per feature is a mean over every order and line: an effect the
    nominal update followed everywhere but in one order -- a crack whose loss of mean
    stiffness the update takes as a softer shaft, leaving only its 2x -- is diluted by
    the others below the no-gap floor. Tested order by order (each floor an effect-free
    quantile with the three orders' Bonferroni share), such a sweep still goes to the
    candidates (:func:`decide`). Empty with the floors unset."""
    return {k: float(mean_z2[k]) for k, f in order_floors(settings).items()
            if k in mean_z2 and mean_z2[k] > f}


def decide(e0: float, ranking: list, settings, n_features: int, orders_over=()):
    """The verdict from the held-out gap per feature and the ranked candidates.

    Returns ``'no-gap'``, the chosen ranking entry, or ``None`` (unexplained); a chosen
    entry without effects (model error only, see :func:`search`) is a ``no-gap`` verdict
    with the model's error stated (:func:`conclude`). Kept
    separate from the search so thresholds can be fixed on pilot trials and then
    applied unchanged to fresh ones.

    A candidate explains the gap when it removes ``min_shrink`` of the held-out excess
    above the effect-free noise (:func:`judged_shrink`) *and* ``min_log_shrink`` of its
    logarithm: the excess is dominated by the few largest features, and an effect that
    matches them while breaking many others (a bearing rattling broadband to mimic an
    electrical line, say) must not pass. The breadth check is waived
    (``breadth_waived_at_floor``) for a candidate that leaves no more than
    ``no_gap_per_feature``: the test that calls a sweep effect-free before any candidate
    then finds nothing left, whatever it broke or left untouched on the way -- on a
    rotor its model does not describe exactly, the model-form residual spread thinly
    over many features is what holds the logarithm's share down, and no effect removes
    that. Which candidate is judged: :func:`preferred`.

    ``orders_over`` (:func:`orders_over_floor`) names the orders whose held-out features
    exceed their own floor: a sweep under ``no_gap_per_feature`` with any is decided as
    one above it (the candidates must explain it, or it is unexplained).

    A sweep under the floor is ``no-gap`` unless ``attribute_below_floor`` is set; then
    a candidate that removes ``min_shrink`` and ``min_log_shrink`` of what is left is
    named (the breadth waiver does not apply there), and the sweep is ``no-gap``
    otherwise, never unexplained.
    """
    under = e0 <= settings.no_gap_per_feature and not orders_over
    if under and not settings.attribute_below_floor:
        return "no-gap"
    # the verdict when no candidate explains the gap: under the floor there is none
    none_named = "no-gap" if under else None
    choice = preferred(ranking, settings, n_features)
    if choice is None:
        return none_named
    return none_named if shortfalls(choice, settings, n_features, under) else choice


def shortfalls(entry: dict, settings, n_features: int, under: bool = False) -> list[str]:
    """The tests of :func:`decide` that the judged candidate ``entry`` fails:
    ``'shrink'`` (it removes less than ``min_shrink`` of the held-out excess above the
    effect-free noise, :func:`judged_shrink`) and
    ``'breadth'`` (less than ``min_log_shrink`` of its logarithm, the waiver at the
    floor not applying); ``under``: the sweep was within the no-gap floor. Empty: the
    candidate is named."""
    left = entry["heldout_gap_after"] / max(n_features, 1)
    # under the floor every candidate leaves no more than it: the waiver would pass any
    waived = (settings.breadth_waived_at_floor and not under
              and left <= settings.no_gap_per_feature)
    failed = []
    if judged_shrink(entry, settings, n_features) < settings.min_shrink:
        failed.append("shrink")
    if entry["log_shrink"] < settings.min_log_shrink and not waived:
        failed.append("breadth")
    return failed


class FrontEnd:
    """What :func:`search` asks of a measurement front end.

    ``fit`` is required; the other hooks default to the plain search (no continued
    lead, every other candidate a partner, no member refits).
    """

    def fit(self, names: tuple) -> CandidateFit:
        """Calibrate the candidate ``names`` (one effect) on the training part."""
        raise NotImplementedError

    def continue_fit(self, fit: CandidateFit) -> CandidateFit | None:
        """A further run of the leading single from its own fit (None: not offered)."""
        return None

    def partners(self, lead: CandidateFit, others: list, k: int) -> list:
        """Up to ``k`` candidates worth pairing with the lead, most promising first."""
        return list(others)[:k]

    def fit_pair(self, lead: CandidateFit, partner: str) -> CandidateFit:
        """Calibrate the lead with ``partner``."""
        raise NotImplementedError

    def refit_members(self, pair: CandidateFit) -> list:
        """Each member of the best pair alone, started from the pair's fit."""
        return []

    def recheck_setting(self, fit: CandidateFit) -> tuple | None:
        """After each other discrete setting of the verdict was refitted from its own
        fit: the verdict's setting entries (``discrete_settings``, ``setting_decided``)
        and the fit of a setting that did better than the verdict's (else None). None:
        nothing to recheck."""
        return None

    def linear_forms(self, fit: CandidateFit) -> list:
        """The candidate refitted with each member that has a linear form
        (:attr:`sknarx.rotor.Effect.linear_form`) in that form: named by its other
        members, the linear form's fit in ``details['model_error']``."""
        return []


def run_parallel(n_jobs, calls, desc):
    """Run ``calls`` (zero-argument callables) on threads with a progress bar; results
    in submission order."""
    gen = Parallel(n_jobs=n_jobs, prefer="threads", return_as="generator")(
        delayed(c)() for c in calls)
    return list(progress_bar(gen, total=len(calls), desc=desc, unit="fit"))


def search(front: FrontEnd, candidates, E0: float, cmp0: pd.DataFrame, n_features: int,
           settings, tick=None) -> list[dict]:
    """Fit every candidate, then pairs where the best single leaves a gap; the ranking.

    1. Every candidate alone (``front.fit``).
    2. The leading single continued from its own fit (``front.continue_fit``), whether
       or not pairs follow: a pair is warm-started from the lead's fit, and the lead
       gets the same chance, so a partner is not credited with the lead's convergence
       and the verdict does not depend on the pair trigger.
    3. If the lead leaves more than ``pair_search_trigger`` (or ``pair_trigger``, the
       smaller) excess per feature: the lead with
       each of up to ``n_partners`` partners (``front.partners``, ``front.fit_pair``);
       each member of the best pair is then refitted alone from it
       (``front.refit_members``) and replaces its single fit where it does better.
    4. Effect or model error: each member that has a linear form (an anisotropy's is
       the isotropic support) of the best single and of the best pair -- the two
       candidates :func:`preferred` chooses between, whatever its thresholds -- is
       refitted in that form (``front.linear_forms``). Where that form scores as well
       (held-out excess plus two per parameter: the restriction costs at most the
       parameter it saves), the member changed the linear rotor only -- model error by
       the rule that separates the two, however much it removed -- and the candidate is
       replaced by its other members with the model error stated (none left: model
       error alone); the replacement's entry says what it replaced (``replaces``), a
       candidate that passed says so (``linear_form_tests``). Repeated until the best
       single and the best pair have both been tested. With ``linear_form_gain`` set, a
       candidate that beats its form by less than that share is out of the verdict
       (:func:`beats_linear_form`), so the contenders are the best single and pair among
       the rest, and the next ones are tested in turn.
    """
    tick = tick or (lambda msg: None)
    singles = run_parallel(settings.n_jobs, [lambda c=c: front.fit((c,)) for c in candidates],
                           "effect candidates")
    tick("single candidates")
    ranked = rank(singles, E0, cmp0)
    if not ranked:
        return ranked
    lead = ranked[0]["_fit"]
    more = front.continue_fit(lead)
    if more is not None:
        if more.heldout_excess < lead.heldout_excess:
            singles = [more if f.names == lead.names else f for f in singles]
            lead = rank(singles, E0, cmp0)[0]["_fit"]
        tick("lead continued")
    pairs = []
    if lead.heldout_excess / n_features > pair_search_from(settings):
        others = [c for c in candidates if (c,) != lead.names]
        partners = front.partners(lead, others, settings.n_partners)
        pairs = run_parallel(settings.n_jobs,
                             [lambda p=p: front.fit_pair(lead, p) for p in partners], "pairs")
        if pairs:
            top = rank(pairs, E0, cmp0)[0]["_fit"]
            for new in front.refit_members(top):
                singles = [new if f.names == new.names
                           and new.heldout_excess < f.heldout_excess else f for f in singles]
        tick("pairs")
    return _without_linear_members(front, singles + pairs, E0, cmp0, tick,
                                   settings.linear_form_gain)


def _contenders(ranked: list) -> list:
    """The best single (model error alone counts as one) and the best pair of a
    ranking: whatever its thresholds, :func:`preferred` chooses between these two."""
    out = []
    for keep in (lambda n: n <= 1, lambda n: n == 2):
        group = [r for r in ranked if keep(len(effect_names(r)))]
        if group:
            out.append(min(group, key=lambda r: r["score"]))
    return out


def _without_linear_members(front, fits, E0, cmp0, tick, gain=None):
    """Step 4 of :func:`search`: the ranking, with the members of its contenders that
    only change the linear rotor replaced by that model error. The contenders are
    those the verdict can still name: a candidate that beat its form by less than
    ``gain`` (:func:`beats_linear_form`) is out of it, and the next best is tested."""
    ranked = rank(fits, E0, cmp0)
    tested = set()
    # model error alone (no member left) has nothing to test
    while todo := [r for r in _contenders([e for e in ranked if beats_linear_form(e, gain)])
                   if r["_fit"].names and r["_fit"].names not in tested]:
        entry = todo[0]
        fit = entry["_fit"]
        tested.add(fit.names)
        alts = front.linear_forms(fit)
        if not alts:
            continue  # no member has a linear form: nothing changed, nothing to re-rank
        tick("effect or model error: " + "+".join(fit.names))
        for alt in alts:
            member = ", ".join(n for n in fit.names if n not in alt.names)
            form = ", ".join(alt.details["model_error"])
            score = alt.heldout_excess + 2.0 * alt.n_params
            if score > entry["score"]:
                # the member did more than a linear change could: an effect
                fit.details.setdefault("linear_form_tests", []).append(
                    {"member": member, "linear_form": form, "heldout_gap_after":
                     alt.heldout_excess, "score": score, "outcome": "effect"})
                continue
            logger.info("%s: the %s did no more than %s (held-out excess %.4g against "
                        "%.4g): model error, not an effect", "+".join(fit.names), member,
                        form, alt.heldout_excess, fit.heldout_excess)
            alt.details["replaces"] = {"effect": list(fit.names), "member": member,
                                       "heldout_gap_after": fit.heldout_excess,
                                       "score": entry["score"]}
            # the candidate gives way to its linear form, which also takes the place of
            # a worse fit of the same members
            fits = [f for f in fits if f is not fit
                    and not (f.names == alt.names and f.heldout_excess >= alt.heldout_excess)]
            fits.append(alt)
            break
        # the tested candidate's entry (or its replacement) carries what the test found
        ranked = rank(fits, E0, cmp0)
    return ranked


def recheck_choice(front: FrontEnd, choice, ranked: list, E0: float, cmp0: pd.DataFrame,
                   settings, n_features: int, e0: float, orders_over=()):
    """Where the verdict has a discrete setting (a crack's station, a rub's disk), each
    other setting refitted from the verdict's own fit (``front.recheck_setting``): a
    setting whose own search missed the basin the chosen one found is no evidence
    against it, and one that now fits the held-out speeds better replaces the verdict's
    fit in the ranking, which is then decided again (once). Only the verdict is
    rechecked (one converged run per other setting). ``e0`` and ``orders_over`` as
    :func:`decide` reads them. Returns the choice and ranking to conclude from."""
    if not isinstance(choice, dict) or "_fit" not in choice:
        return choice, ranked
    out = front.recheck_setting(choice["_fit"])
    if not out:
        return choice, ranked
    entries, better = out
    if better is None:
        choice.update(entries)
        choice["_fit"].details.update(entries)
        return choice, ranked
    better.details.update(entries)
    fits = [better if r is choice else r["_fit"] for r in ranked]
    ranked = rank(fits, E0, cmp0)
    return decide(e0, ranked, settings, n_features, orders_over), ranked


def conclude(choice, ranking: list, cmp0: pd.DataFrame, where: list, settings,
             n_features: int | None = None) -> dict:
    """The document's verdict entries from :func:`decide`'s ``choice``: the verdict, the
    shrink of the held-out gap (for ``unexplained``, what the best candidate removed),
    and with a verdict its bootstrap band, the gap after and each region before and
    after; ``model_error`` where the chosen candidate carries one (the linear form of a
    member that was no effect, see :func:`search`) and ``setting_decided`` where it has
    discrete settings (see :func:`setting_support`); ``rival_pair`` where a pair would
    have been named but for the rival test (:func:`rival_pair_set_aside`) and
    ``pair_under_trigger`` where it would have been but for the pair trigger
    (:func:`pair_under_trigger`); for
    ``unexplained``, ``closest`` (:func:`closest`). ``n_features``: the held-out
    features :func:`decide` was given (default: the rows of ``cmp0``)."""
    if choice == "no-gap":
        return {"verdict": "no-gap", "shrink": 0.0}
    n_features = max(len(cmp0) if n_features is None else n_features, 1)
    aside = rival_pair_set_aside(ranking, settings, n_features)
    # what the verdict rule set aside, said beside whatever it names
    notes = {"rival_pair": aside} if aside is not None else {}
    under = pair_under_trigger(ranking, settings, n_features)
    if under is not None:
        notes["pair_under_trigger"] = under
    if choice is None:
        near = closest(ranking, settings, n_features)
        return {"verdict": "unexplained",
                "shrink": max(ranking[0]["shrink"], 0.0) if ranking else 0.0, **notes,
                **({"closest": near} if near is not None else {})}
    cmp = choice["_cmp"]
    gap_after = {"heldout_excess": choice["heldout_gap_after"],
                 "rms_gap_m": float(np.sqrt(np.mean(cmp["gap"] ** 2)))}
    extra = {"model_error": choice["model_error"]} if choice.get("model_error") else {}
    extra.update(notes)
    if not effect_names(choice):  # model error alone explains the gap: no effect
        return {"verdict": "no-gap", "shrink": 0.0, "gap_after": gap_after, **extra}
    if "setting_decided" in choice:
        # a crack's station or a rub's disk the held-out speeds did not decide is said
        # so beside the verdict, not only in the ranking
        extra["setting_decided"] = choice["setting_decided"]
    return {"verdict": choice["effect"], "shrink": choice["shrink"],
            "shrink_above_noise": judged_shrink(choice, settings, n_features),
            "shrink_band": bootstrap_shrink(cmp0, cmp, settings.n_bootstrap, settings.seed),
            "gap_after": gap_after, "regions_after": regions_after(where, cmp, cmp0),
            **extra}


def closest(ranking: list, settings, n_features: int) -> dict | None:
    """For an ``unexplained`` verdict, the candidate the verdict judged
    (:func:`preferred`) and why it was not named: its ``effect``, ``shrink``,
    ``log_shrink`` and ``heldout_gap_after``, the tests it fails (``short_of``, see
    :func:`shortfalls`) and the thresholds they hold it to. None without a candidate."""
    judged = preferred(ranking, settings, n_features)
    if judged is None:
        return None
    return {"effect": judged["effect"], "shrink": float(judged["shrink"]),
            "shrink_above_noise": float(judged_shrink(judged, settings, n_features)),
            "log_shrink": float(judged["log_shrink"]),
            "heldout_gap_after": float(judged["heldout_gap_after"]),
            "short_of": shortfalls(judged, settings, n_features),
            "min_shrink": settings.min_shrink, "min_log_shrink": settings.min_log_shrink}


#: a verdict's entries that describe the fit of the effect it names
_NAMED_FIT = ("shrink_band", "gap_after", "regions_after", "setting_decided", "model_error",
              "rotor_reading")


def with_passes(result, comparison):
    """A diagnosis (:class:`~sknarx.gap.GapDiagnosis`) with the test of two passes of its
    sweep (:class:`~sknarx.gap.passes.PassComparison`; None: ``result`` as it is).

    The document gains ``passes`` (the comparison's ``to_dict``). Where the passes
    differ, the rotor changed between them. No candidate of the library, each
    time-invariant, explains that, so the verdict becomes ``unexplained``. What the
    first pass alone concluded moves to ``passes["one_pass"]``: its verdict and the
    entries that describe the named effect's fit. Its table after the fit moves too, to
    ``tables["after_one_pass"]``. The ranking stays: it is the best time-invariant
    reading of the first pass.
    """
    if comparison is None:
        return result
    doc = result.document
    entry = comparison.to_dict()
    if comparison.changed:
        entry["one_pass"] = {"verdict": doc["verdict"],
                             **{k: doc.pop(k) for k in _NAMED_FIT if k in doc}}
        doc["verdict"] = "unexplained"
        if "after" in result.tables:
            result.tables["after_one_pass"] = result.tables.pop("after")
    doc["passes"] = entry
    return result


def public_ranking(ranking: list, settings=None, n_features: int = 1) -> list[dict]:
    """The ranking as it goes into the document (the core's own keys dropped); with
    ``settings``, each entry with the share the verdict judges it by
    (``shrink_above_noise``, :func:`judged_shrink`)."""
    return [{**{k: v for k, v in r.items() if not k.startswith("_")},
             **({"shrink_above_noise": judged_shrink(r, settings, n_features)}
                if settings is not None else {})} for r in ranking]
