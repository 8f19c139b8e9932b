"""The verdict rule: the ten values that decide ``no-gap``, an effect, a pair or
``unexplained``, and how they decide it."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from numbers import Real

from scipy.stats import chi2, norm
from sklearn.utils._param_validation import Interval, validate_parameter_constraints

from .candidate import Candidate, NoiseFloor, Shortfall, Verdict

__all__ = ["VerdictRule", "ORDER_DOMAIN_RULE"]


@dataclass(frozen=True)
class VerdictRule:
    """The values that decide a gap diagnosis's verdict, and the comparison's tolerances.

    A sweep whose held-out gap is within what its measured noise leaves is within the
    floor; a candidate is *named* when it explains most of the gap above the noise and
    explains it broadly; a pair replaces its lead only where the lead leaves a gap and
    the pair removes a share of it. Every value that changes a verdict is here; how hard
    the search tries is :class:`~sknarx.gap.SearchBudget`'s.

    Parameters
    ----------
    false_alarm : float, default=0.01
        Chance that measurement noise alone is taken for a gap. The no-gap floor is the
        ``1 - false_alarm`` quantile of the held-out excess that noise at the measured
        standard errors leaves (:func:`sknarx.gap.floor.noise_floor`); two passes
        differ beyond the normal point ``1 - false_alarm``; a gap region's features
        exceed the chi-square (2 dof) point; a discrete setting is *decided* where the
        held-out speeds prefer it in ``1 - false_alarm`` of bootstrap resamples.
        Stated, not fitted.
    min_shrink : float, default=0.6
        Share of the held-out gap above the noise a named effect removes: it explains
        most of the gap. Tuned: see docs/gap.md, *The verdict rule*.
    min_log_shrink : float, default=0.3
        Share of ``sum(log(1 + excess))`` a named effect removes: it explains the gap
        broadly, not its few largest features only (waived where the effect leaves no
        more than the floor). Tuned: see docs/gap.md, *The verdict rule*.
    pair_trigger : float, default=0.5
        A pair may be named only where the best single leaves more than this held-out
        excess per feature. Tuned: see docs/gap.md, *The verdict rule*.
    min_gain : float, default=0.3
        Share of what a simpler candidate leaves that a richer one must remove to be
        preferred: a pair over its lead, an effect over its linear form (a change of
        the linear rotor, which is model error). Tuned for pairs (docs/gap.md,
        *The verdict rule*); the same share for the linear form.
    rtol : float, default=0.01
        Share of its size to which two descriptions of one rotor agree on a vector
        beyond noise: a calibrated model's 1x and the rig's (the model-form error no
        calibration removes), and two passes of an unchanged rig (what it does not
        repeat: the real RK-4 rig's repeats differ by 0.2-0.7 % of a 1x). Stated.
    harmonic_rtol : float, default=0.3
        Share of its size to which two derivations of one contact law agree on a
        harmonic (1/3x to 3x). Measured: sknarx's and ROSS's journals' 2x differ by
        2-47 %, median 25 %, for the same bearings.
    line_sigmas : float, default=3.0
        Standard errors within which a non-synchronous line energy agrees (a
        periodogram line's amplitude is far from Gaussian). Stated.
    keyphasor_deg : float, default=5.0
        Largest phase offset (degrees) of the once-per-revolution reference a speed
        step may have: removed before comparing, ``k`` times for order ``k``. Stated.
    speed_rtol : float, default=0.005
        Two passes' speed steps are one step where their speeds agree to this share (a
        rig's speed control repeats a step to a fraction of a per cent; a step moved
        within it is compared at the first pass's slope). Stated.

    Examples
    --------
    >>> from sknarx.gap import VerdictRule
    >>> rule = VerdictRule()
    >>> round(rule.pass_sigmas, 3), round(rule.region_z2, 2)
    (2.326, 9.21)
    >>> VerdictRule(min_shrink=1.5)
    Traceback (most recent call last):
    ...
    sklearn.utils._param_validation.InvalidParameterError: The 'min_shrink' parameter of ...
    """

    false_alarm: float = 0.01
    min_shrink: float = 0.6
    min_log_shrink: float = 0.3
    pair_trigger: float = 0.5
    min_gain: float = 0.3
    rtol: float = 0.01
    harmonic_rtol: float = 0.3
    line_sigmas: float = 3.0
    keyphasor_deg: float = 5.0
    speed_rtol: float = 0.005

    _parameter_constraints = {
        "false_alarm": [Interval(Real, 0, 0.5, closed="neither")],
        "min_shrink": [Interval(Real, 0, 1, closed="right")],
        "min_log_shrink": [Interval(Real, 0, 1, closed="both")],
        "pair_trigger": [Interval(Real, 0, None, closed="left")],
        "min_gain": [Interval(Real, 0, 1, closed="left")],
        "rtol": [Interval(Real, 0, 1, closed="left")],
        "harmonic_rtol": [Interval(Real, 0, 10, closed="both")],
        "line_sigmas": [Interval(Real, 0, None, closed="neither")],
        "keyphasor_deg": [Interval(Real, 0, 90, closed="both")],
        "speed_rtol": [Interval(Real, 0, 0.5, closed="left")],
    }

    def __post_init__(self):
        validate_parameter_constraints(self._parameter_constraints, asdict(self),
                                       caller_name=type(self).__name__)

    def to_dict(self) -> dict:
        """The rule as plain values (the document's ``settings["rule"]``)."""
        return asdict(self)

    # ------------------------------------------------------------- derived levels
    @property
    def pass_sigmas(self) -> float:
        """The two-pass test's threshold: the normal deviate of upper tail
        ``false_alarm``."""
        return float(norm.isf(self.false_alarm))

    @property
    def region_z2(self) -> float:
        """The z2 above which a feature counts toward a gap region: the chi-square (2
        degrees of freedom) point of upper tail ``false_alarm``, ``-2 ln(false_alarm)``."""
        return -2.0 * math.log(self.false_alarm)

    @property
    def setting_support(self) -> float:
        """The bootstrap share at which the held-out speeds decide a discrete setting."""
        return 1.0 - self.false_alarm

    # ------------------------------------------------------------------- the rule
    def decide(self, e0: float, ranking: list, floor: NoiseFloor | None,
               n_features: int) -> Verdict:
        """The verdict from the held-out gap per feature ``e0`` before any candidate and
        the ranked candidates (:class:`~sknarx.gap.candidate.Candidate`).

        The candidate judged is the best single, or the best pair where it earns its
        place (:meth:`preferred`). It is named when it removes ``min_shrink`` of the
        held-out gap above the noise and ``min_log_shrink`` of its logarithm; the
        breadth test is waived when it leaves no more than the floor, where what it
        left cannot be told from noise. Otherwise the verdict is ``no-gap`` when the gap
        was within the floor (``floor``: :func:`sknarx.gap.floor.noise_floor`; None:
        never within it) and ``unexplained`` when it was not. A named candidate with no
        effect (a member's linear form replaced it: model error) is ``no-gap``.
        """
        n = max(int(n_features), 1)
        within = floor is not None and e0 <= floor.floor
        passed_over = "no-gap" if within else "unexplained"
        choice, set_aside = self.preferred(ranking, floor, n)
        if choice is None:
            return Verdict(passed_over, None, [], set_aside, within, e0, floor)
        short = self.shortfalls(choice, floor, n, within)
        if short:
            return Verdict(passed_over, choice, short, set_aside, within, e0, floor)
        outcome = "effect" if choice.effects else "no-gap"
        return Verdict(outcome, choice, [], set_aside, within, e0, floor)

    def shortfalls(self, candidate: Candidate, floor: NoiseFloor | None, n_features: int,
                   within: bool = False) -> list[Shortfall]:
        """The naming tests ``candidate`` fails (empty: it is named). ``within``: the
        gap before any candidate was within the floor (no breadth waiver then)."""
        n = max(int(n_features), 1)
        out = []
        share = candidate.shrink_above(floor, n)
        if share < self.min_shrink:
            out.append(Shortfall("shrink", share, self.min_shrink))
        waived = (floor is not None and not within
                  and candidate.heldout_after / n <= floor.floor)
        if candidate.log_shrink < self.min_log_shrink and not waived:
            out.append(Shortfall("breadth", candidate.log_shrink, self.min_log_shrink))
        return out

    def preferred(self, ranking: list, floor: NoiseFloor | None, n_features: int):
        """``(judged, set_aside)``: the best single (model error alone counts as one),
        or the best pair where the best single leaves more than ``pair_trigger`` per
        feature, the pair removes ``min_gain`` of what it leaves and more than noise
        could (its excess lower by the chi-square point of its added parameters at
        ``false_alarm``), and its members are not rivals (each alone would be named by
        its shrink). Candidates whose member does
        too little beyond its linear form are left out (:meth:`beyond_linear_form`).
        ``set_aside``: ``[(pair, Shortfall)]`` for a pair kept out by the trigger or the
        rival test alone."""
        n = max(int(n_features), 1)
        ranking = [c for c in ranking if not self.beyond_linear_form(c)]
        singles = [c for c in ranking if len(c.effects) <= 1]
        pairs = [c for c in ranking if len(c.effects) == 2]
        if not singles:
            return None, []
        best = min(singles, key=lambda c: c.score)
        if not pairs:
            return best, []
        pair = min(pairs, key=lambda c: c.score)
        left = best.heldout_after
        gain = 1.0 - pair.heldout_after / left if left > 0 else 0.0
        # what the pair removes beyond its lead is more than noise could (a likelihood
        # ratio on the chi-square scale, at the rule's false-alarm level) and is a
        # practical share of what the lead leaves
        added = max(pair.n_params - best.n_params, 1)
        if gain < self.min_gain or left - pair.heldout_after <= chi2.isf(self.false_alarm,
                                                                          added):
            return best, []
        failed = []
        if left / n <= self.pair_trigger:
            failed.append(Shortfall("pair-trigger", left / n, self.pair_trigger))
        alone = self.shrinks_alone(singles, floor, n)
        members = [alone.get(m, -math.inf) for m in pair.effects]
        if min(members) >= self.min_shrink:
            failed.append(Shortfall("rival", min(members), self.min_shrink))
        if not failed:
            return pair, []
        return best, [(pair, failed[0])] if len(failed) == 1 else []

    def beyond_linear_form(self, candidate: Candidate) -> list[Shortfall]:
        """The linear-form tests ``candidate`` fails: each member tested against its
        linear form (``details["linear_form_tests"]``, see
        :func:`sknarx.gap.search.search`) must remove ``min_gain`` of what that form
        leaves. On a rotor the model does not describe exactly a member's extra
        parameters always buy some model-form error, so scoring better than the form
        is not enough."""
        out = []
        for test in candidate.details.get("linear_form_tests", ()):
            left = test["heldout_gap_after"]
            removed = 1.0 - candidate.heldout_after / left if left > 0 else 0.0
            if removed < self.min_gain:
                out.append(Shortfall("linear-form", removed, self.min_gain))
        return out

    @staticmethod
    def shrinks_alone(ranking: list, floor: NoiseFloor | None, n_features: int) -> dict:
        """The share of the gap above the noise each effect fitted alone removes, by
        name (its best single fit where it was fitted more than once)."""
        alone: dict[str, float] = {}
        for c in ranking:
            if len(c.effects) == 1:
                name = c.effects[0]
                alone[name] = max(alone.get(name, -math.inf),
                                  c.shrink_above(floor, n_features))
        return alone


#: The order-domain front end's rule (:mod:`sknarx.bode.diagnosis`). A 1x Bode record
#: has one feature per speed bin and two candidates and their pair: a verdict removes
#: half the held-out gap and need not show breadth, a pair is always weighed against
#: its lead (by the search's AIC ranking), and a 1x bin agrees to 2 % of its size.
#: Stated, not tuned: no pilot trials of this front end exist.
ORDER_DOMAIN_RULE = VerdictRule(min_shrink=0.5, min_log_shrink=0.0, pair_trigger=0.0,
                                min_gain=0.0, rtol=0.02)
