"""Thresholds and search effort of the gap diagnosis.

The no-gap threshold and the per-order floors are noise floors measured on effect-free
trials; the shrink and pair thresholds were fitted on the own family's pilot trials
of ``benchmarks/bench_gap_blind.py``, and four settings were chosen on the logged
trials of the independent plants before fresh seeds scored them; all are frozen here.
Which trials set each value and where it was then scored blind is a table in
docs/gap.md (*Where the frozen settings come from*); the comments below say why each is
there. The search-effort fields decide what is computed (the benchmark reuses a logged
trial only if they match).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

__all__ = ["DiagnosisSettings", "ORDER_DOMAIN_SETTINGS", "SEARCH_FIELDS"]

#: the fields that change what a diagnosis computes (the others only read its results)
SEARCH_FIELDS = ("pair_trigger", "pair_search_trigger", "n_partners", "max_nfev",
                 "transient_s", "settle_s",
                 "update_nominal", "update_max_nfev", "update_spread", "seed",
                 "warm_lead_s", "n_probe", "jacobian_refresh", "settled_sigma",
                 "step_factor", "probes_per_parameter", "pair_probes_per_parameter",
                 "pair_short_starts", "reading_contenders")


@dataclass(frozen=True)
class DiagnosisSettings:
    """Frozen thresholds and search effort (docs/gap.md: where each was set).

    Each value is checked when the settings are made: one out of its range (a negative
    floor, a share of 1 or more, a count of 0, a NaN) raises a ``ValueError`` naming the
    field and its range.

    Examples
    --------
    >>> from dataclasses import replace
    >>> from sknarx.gap import DiagnosisSettings
    >>> replace(DiagnosisSettings(), pass_rtol=0.03).pass_rtol
    0.03
    >>> DiagnosisSettings(pass_rtol=1.5)
    Traceback (most recent call last):
    ...
    ValueError: DiagnosisSettings.pass_rtol must be a finite number in [0, 1), got 1.5.
    """

    # the verdict thresholds are fitted by benchmarks/bench_gap_blind.py and frozen here
    # (docs/gap.md, *Where the frozen settings come from*)
    no_gap_per_feature: float = 0.340  # mean held-out excess per feature below which: no-gap
    min_shrink: float = 0.6  # a verdict must remove at least this share of the gap
    # ... of the gap above the effect-free noise: the median held-out excess per feature
    # of effect-free sweeps (the own family's 20 null trials, whose 99 % quantile is
    # no_gap_per_feature), which no candidate can remove -- near the floor it is a third
    # of the gap, and the plain share asked a mild effect to remove part of it too. A
    # candidate's share for the verdict is (E0 - E) / (E0 - n * noise_per_feature), the
    # plain (E0 - E) / E0 where the gap is not above the noise or with None
    # (sknarx.gap.core.judged_shrink; docs/gap_validation.md, *The noise-referenced
    # shrink made the package's rule*)
    noise_per_feature: float | None = 0.112
    min_log_shrink: float = 0.3  # ... and this share of sum(log(1 + excess))
    # ... unless it leaves no more than no_gap_per_feature: what is left then cannot be
    # told from an effect-free sweep, so the breadth check has nothing to guard
    # (sknarx.gap.core.decide; docs/gap.md, *Verdict*)
    breadth_waived_at_floor: bool = True
    # a sweep under the floor (every order too) is still attributed to the candidate
    # that passes min_shrink and min_log_shrink of what is left (the breadth check not
    # waived); False: under the floor is no-gap before any candidate. An effect the
    # nominal update mostly followed still leaves a signature under the floor, and a
    # candidate must still pass both shrinks of what is left to be named. It costs every
    # effect-free sweep the candidate search, about ten times the diagnosis without it
    attribute_below_floor: bool = True
    # each order's held-out features are also tested on their own: a sweep under
    # no_gap_per_feature still goes to the candidates when the mean z2 of its held-out
    # 1x, 2x or 3x features exceeds that order's floor (sknarx.gap.core.orders_over_floor).
    # An effect the nominal update followed but in one order (a crack's 2x) is diluted
    # in the mean over every feature. Each floor is the 1 - 0.01/3 quantile (log-normal,
    # Bonferroni over the three orders) of that mean on effect-free trials, measured
    # and frozen like no_gap_per_feature; None: the mean over every feature alone decides
    order_floors_z2: tuple[float, float, float] | None = (2.48, 1.81, 1.76)
    # try pairs when the best single leaves this excess per feature, and a pair must
    # remove pair_gain of what the best single leaves; frozen on own-family pilot trials
    # like the rest (a lower trigger and a stricter gain chosen on an independent
    # plant's logs lost right verdicts on both independent plants when scored blind)
    pair_trigger: float = 0.5
    pair_gain: float = 0.3
    # pairs are searched (fitted, ranked and listed) wherever the best single leaves
    # more than the smaller of this and pair_trigger, and named only above
    # pair_trigger: a weak second effect beside a dominant one shows in the ranking
    # before the verdict may name it. The verdicts do not depend on it; the rankings
    # do: decided before fresh pair trials were drawn, a search from 0.1 ranked more
    # pairs in the top two than one from 0.2 and lost none (docs/gap.md, *The pair
    # search from 0.1*), at about 53 s more where the best single leaves 0.1-0.2
    pair_search_trigger: float = 0.1
    # ... and score (AIC: held-out excess + 2 per parameter) this much below it; None: the
    # gain alone decides
    pair_margin: float | None = None
    # ... and not both of its members, each fitted alone, remove this share of the
    # held-out gap: two candidates that each explain most of it are rival readings of
    # one signature, and together they fit what the lead's form leaves of a rotor it
    # does not describe exactly -- on both independent plants a rub came out as rub +
    # crack (the crack alone removing 0.84-0.99) and a crack as crack + misalignment --
    # while a true pair's weaker member alone removed at most 0.69; 0.7-0.9 did the same
    # and the middle is taken; None: no such test
    pair_rival_shrink: float | None = 0.8
    # a candidate whose member has a linear form (an anisotropy's is the isotropic
    # support) is judged only if that member removes this share of what its linear form
    # leaves (sknarx.gap.core.beats_linear_form): less is what a change of the linear
    # rotor explains -- model error, by the rule that separates the two. Set at
    # pair_gain's value (0.3, what a pair's second member must remove too); None: the
    # search's own test (the member scores better than its form) alone
    linear_form_gain: float | None = 0.3
    n_partners: int = 3  # partners tried with the best single (probed on top of its fit)
    max_nfev: int = 15
    # Sobol settings of a candidate's parameters scored before its local runs: a rub's
    # contact regime (clearance against orbit and stator offset, 5 parameters) is a
    # small corner of its range that 16 settings missed on an independent plant (shrink
    # 0.52 against 0.955 with 64; each probe is one warm-started evaluation), and 64
    # left three rubs of the two independent plants in a basin with the stator pushed
    # sideways, where 128 found the contact on the bearing line at no more cost
    n_probe: int = 128
    # ... at most this many per probed parameter (rounded up to a power of two): a
    # one-parameter clearance gets 16, a two-parameter looseness 32, a four-parameter
    # crack 64, a five-parameter rub or misalignment 128
    probes_per_parameter: int | None = 16
    # a pair's partner is probed (and then fitted) on top of the lead's converged fit,
    # a better informed start than a single's: half the probes per parameter and half
    # the short local runs per discrete setting (calibrate's n_short: 4 for singles)
    pair_probes_per_parameter: int | None = 8
    pair_short_starts: int = 2
    transient_s: float = 0.5  # transient window of records that start with a transient
    # records found settled (see features.free_response_decay) are compared with
    # simulations settled this long first: five time constants of the paper rotor's
    # slowest lightly damped mode (see RotorBearingSimulator.simulate)
    settle_s: float = 2.0
    # a calibration's local search continues the settled runs of its start from this
    # long before each record (s) instead of settling every evaluation from rest for
    # settle_s (see SweepModel.warmed); None: always from rest
    warm_lead_s: float | None = 0.3
    # update the nominal rotor's linear parameters on the training speeds' steady 1x
    # before any effect is blamed (sknarx.gap.updating): what the update explains is
    # model error and is reported as such
    update_nominal: bool = True
    update_max_nfev: int = 30
    # widen each harmonic's and line's model-form tolerance by its spread over the
    # update's posterior (sknarx.gap.diagnosis._prediction_spread): the 1x-fitted update
    # leaves the contact's harmonics uncertain (one simulated sweep per sigma point)
    update_spread: bool = True
    # a calibration's local runs difference their Jacobian every this many steps and
    # update it by Broyden's secant rule in between (sknarx.gap.jacobian); None:
    # forward differences at every step (one simulated sweep per parameter each)
    jacobian_refresh: int | None = 4
    # a calibration's converged run stops once a step moved no parameter by more than
    # this share of its standard error (sknarx.gap.jacobian.SettledStop); None: it runs
    # to max_nfev or scipy's tolerances
    settled_sigma: float | None = 0.1
    # the simulator's integration step for every sweep the diagnosis runs (h |lambda|max
    # <= step_factor; RK4 is stable to ~2.8): 2.5 takes 4 steps per 1 kHz sample on the
    # paper rotor instead of the simulator's default 5, a fifth less per evaluation,
    # and moves the features by a small share of their standard errors
    step_factor: float = 2.5
    # a discrete setting (a crack's station, a rub's disk, a misalignment's end) is
    # reported as decided where the held-out speeds prefer it over every other setting
    # in this share of bootstrap resamples (sknarx.gap.core.setting_support): stated,
    # like the shrink's 5-95 % band, not fitted
    decided_setting_support: float = 0.95
    # with alternative rotor readings (diagnose's ``readings``), the primary ranking's
    # best singles fitted again in each reading (sknarx.gap.readings): the search in a
    # reading is the whole search over these, so its cost grows with them
    reading_contenders: int = 2
    # two passes of one sweep (a run-up and its coast-down, sknarx.gap.passes) differ
    # when their shaft orders' differences beyond a dead band, squared over their noise
    # and summed, stand this far out as a normal deviate of equal upper tail under noise
    # alone: the larger of a normal's one-sided 1 % point and the 99 % point of a normal
    # fitted to effect-free pairs of passes of the own family, measured and frozen like
    # no_gap_per_feature (benchmarks/bench_gap_passes.py --null)
    pass_floor_sigmas: float = 2.326
    # ... whose steps are the same step where their speeds agree to this share
    pass_speed_rtol: float = 0.005
    # ... the dead band: this share of a vector's size, what a rig does not repeat between
    # two records of an unchanged rotor (the RK-4 rig's repeats differ by 0.2-0.7 % of a
    # 1x beyond their noise: benchmarks/bench_gap_passes_real.py). It sets the smallest
    # change the test sees; a rig that repeats better may lower it, after checking its
    # own repeats against it
    pass_rtol: float = 0.01
    n_jobs: int = 1  # candidates in sequence: each evaluation already uses both cores
    n_bootstrap: int = 200
    seed: int = 0

    def __post_init__(self):
        # a settings object is built once and read deep inside a long diagnosis: a value
        # out of its range is named here, not found as a wrong verdict an hour later
        for name, (low, high, closed, optional) in _RANGES.items():
            _check_range(name, getattr(self, name), low, high, closed, optional)
        for name in _INTEGERS:
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool)
                                      or not isinstance(value, numbers.Integral)):
                raise ValueError(f"DiagnosisSettings.{name} must be a whole number, got "
                                 f"{value!r}.")
        for name in _FLAGS:
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"DiagnosisSettings.{name} must be True or False, got "
                                 f"{getattr(self, name)!r}.")
        if self.n_jobs == 0:
            raise ValueError("DiagnosisSettings.n_jobs must not be 0 (1: in sequence; -1: "
                             "every core).")
        floors = self.order_floors_z2
        if floors is not None:
            if len(floors) != 3:
                raise ValueError("DiagnosisSettings.order_floors_z2 holds the 1x, 2x and 3x "
                                 f"floors (three numbers) or is None, got {floors!r}.")
            for order, value in zip(("1x", "2x", "3x"), floors, strict=True):
                _check_range(f"order_floors_z2 ({order})", value, 0.0, math.inf,
                             (False, False), False)


def _check_range(name, value, low, high, closed, optional):
    """Raise a ValueError naming ``name`` unless ``value`` is a finite number in the range
    (``closed``: whether each end is allowed; ``optional``: None too)."""
    if value is None and optional:
        return
    # an infinite end that the range closes is a value (a floor no sweep is over)
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and \
        (math.isfinite(value) or (value == high == math.inf and closed[1]))
    if ok:
        ok = (value >= low if closed[0] else value > low) and \
            (value <= high if closed[1] else value < high)
    if not ok:
        span = f"{'[' if closed[0] else '('}{low:g}, {high:g}{']' if closed[1] else ')'}"
        kind = "a number" if high == math.inf and closed[1] else "a finite number"
        raise ValueError(f"DiagnosisSettings.{name} must be {kind} in {span}"
                         f"{' or None' if optional else ''}, got {value!r}.")


_INF = math.inf
# ranges as (low, high, (low allowed, high allowed), None allowed)
_AT_LEAST_0 = (0.0, _INF, (True, False), False)
_POSITIVE = (0.0, _INF, (False, False), False)
_AT_LEAST_1 = (1, _INF, (True, False), False)
_AT_MOST_1 = (-_INF, 1.0, (False, True), False)
_SHARE = (0.0, 1.0, (True, True), False)
_SHARE_BELOW_1 = (0.0, 1.0, (True, False), False)
_FINITE = (-_INF, _INF, (False, False), False)


def _or_none(span):
    return (*span[:3], True)


#: each numeric field's range
_RANGES = {
    # inf: every sweep is within the floor (the benchmarks' effect-free trials, which
    # measure the gap before any effect to set the floor, use it)
    "no_gap_per_feature": (0.0, _INF, (True, True), False), "min_shrink": _AT_MOST_1,
    "noise_per_feature": _or_none(_AT_LEAST_0),
    "min_log_shrink": _AT_MOST_1, "pair_trigger": _AT_LEAST_0, "pair_gain": _SHARE,
    "pair_search_trigger": _AT_LEAST_0, "pair_margin": _or_none(_AT_LEAST_0),
    "pair_rival_shrink": _or_none(_AT_MOST_1), "linear_form_gain": _or_none(_SHARE),
    "n_partners": _AT_LEAST_0, "max_nfev": _AT_LEAST_1, "n_probe": _AT_LEAST_1,
    "probes_per_parameter": _or_none(_AT_LEAST_1),
    "pair_probes_per_parameter": _or_none(_AT_LEAST_1), "pair_short_starts": _AT_LEAST_0,
    "transient_s": _AT_LEAST_0, "settle_s": _AT_LEAST_0,
    "warm_lead_s": _or_none(_AT_LEAST_0), "update_max_nfev": _AT_LEAST_1,
    "jacobian_refresh": _or_none(_AT_LEAST_1), "settled_sigma": _or_none(_POSITIVE),
    "step_factor": _POSITIVE, "decided_setting_support": (0.0, 1.0, (False, True), False),
    "reading_contenders": _AT_LEAST_0, "pass_floor_sigmas": _FINITE,
    "pass_speed_rtol": _SHARE_BELOW_1, "pass_rtol": _SHARE_BELOW_1, "n_jobs": _FINITE,
    "n_bootstrap": _AT_LEAST_0, "seed": _AT_LEAST_0,
}
#: the fields that count something
_INTEGERS = ("n_partners", "max_nfev", "n_probe", "probes_per_parameter",
             "pair_probes_per_parameter", "pair_short_starts", "update_max_nfev",
             "jacobian_refresh", "reading_contenders", "n_jobs", "n_bootstrap", "seed")
#: the switches
_FLAGS = ("breadth_waived_at_floor", "attribute_below_floor", "update_nominal",
          "update_spread")


#: The order-domain front end's verdict rule (:mod:`sknarx.gap.orderdomain`). A 1x Bode
#: record has one feature per speed bin and two candidates and a pair, so no pilot
#: trials fit these; they are stated, not tuned: a verdict removes half the held-out gap
#: and does not widen it (its log-excess does not grow); the pair is always tried and
#: replaces its better member when its AIC is 10 lower (strong evidence on the
#: chi-square scale); no noise floor or noise median is claimed (a record whose held-out
#: bins all agree within their scatter is ``no-gap``), and with the 1x alone there are no
#: orders to test on their own; 300 bootstrap draws.
ORDER_DOMAIN_SETTINGS = DiagnosisSettings(
    no_gap_per_feature=0.0, order_floors_z2=None, min_shrink=0.5, noise_per_feature=None,
    min_log_shrink=0.0,
    pair_trigger=0.0, pair_gain=0.0, pair_margin=10.0, pair_rival_shrink=None,
    n_bootstrap=300, seed=0)
