"""How hard a gap diagnosis searches: effort only, never how a fit is judged."""

from __future__ import annotations

from dataclasses import asdict, dataclass
from numbers import Integral, Real

from sklearn.utils._param_validation import (
    Interval,
    StrOptions,
    validate_parameter_constraints,
)

__all__ = ["SearchBudget"]


@dataclass(frozen=True)
class SearchBudget:
    """The search effort of a gap diagnosis.

    Every field changes how many simulations a diagnosis spends and so how close its
    fits come to their best, never the test a fit is judged by
    (:class:`~sknarx.gap.VerdictRule` holds those). More effort can only find better
    fits; less makes a diagnosis faster and its rankings coarser.

    Parameters
    ----------
    max_nfev : int, default=15
        Function evaluations of a candidate's converged least-squares run.
    n_probe : int, default=128
        Most Sobol settings of a candidate's parameters scored before its local runs
        (periodic parameters such as a crack's angle have several basins).
    probes_per_parameter : int, default=16
        At most this many probes per probed parameter, rounded up to a power of two.
    pair_probes_per_parameter : int, default=8
        The same for a pair's partner, probed on top of the lead's converged fit.
    short_starts : int, default=4
        Best probes of a single that get a short local run before the best converges.
    pair_short_starts : int, default=2
        The same for a pair's partner.
    n_partners : int, default=3
        Partners tried with the best single.
    pair_search_from : float, default=0.1
        Pairs are fitted and ranked wherever the best single leaves more than this
        held-out excess per feature (the rule's ``pair_trigger`` decides whether one
        is named; pairs searched below it are only ranked and reported).
    update_max_nfev : int, default=30
        Function evaluations of the nominal model update.
    jacobian_refresh : int or None, default=4
        A short run's Jacobian is differenced every this many steps and updated by
        Broyden's rule in between; None differences it at every step.
    settled_sigma : float or None, default=0.1
        A converged run stops once a step moved no parameter by more than this share of
        its standard error; None runs to ``max_nfev``.
    warm_lead_s : float or None, default=0.3
        A local run continues its start's settled runs from this long (s) before each
        record instead of settling from rest; None settles every evaluation from rest.
    settle_s : float, default=2.0
        Settling time (s) simulated before the records of a settled sweep: five time
        constants of the paper rotor's slowest lightly damped mode.
    step_factor : float, default=2.5
        Integration step of every simulation, ``h |lambda|max <= step_factor`` (RK4 is
        stable to about 2.8).
    solver : {"integrate", "harmonic-balance"}, default="integrate"
        How a settled record is computed: integrated through ``settle_s``
        (``warm_lead_s`` in a local run), or its shaft-periodic steady state solved
        directly where the rotor and its effects have one (:mod:`sknarx.rotor.steady`;
        the others integrated). The balance makes a diagnosis about 1.5 times faster
        but does not yet give the integrator's verdicts on every sweep it was checked
        on (``docs/decisions.md``), so it is not the default.
    reading_contenders : int, default=2
        Best singles fitted again in each alternative reading of the rotor.
    n_bootstrap : int, default=200
        Bootstrap resamples of the held-out speeds (shrink band, setting support) and
        noise draws of the no-gap floor.
    random_state : int, default=0
        Seed of the probes, the bootstraps and the noise draws.

    Examples
    --------
    >>> from sknarx.gap import SearchBudget
    >>> SearchBudget(max_nfev=5).max_nfev
    5
    >>> SearchBudget(n_probe=0)
    Traceback (most recent call last):
    ...
    sklearn.utils._param_validation.InvalidParameterError: The 'n_probe' parameter of ...
    """

    max_nfev: int = 15
    n_probe: int = 128
    probes_per_parameter: int = 16
    pair_probes_per_parameter: int = 8
    short_starts: int = 4
    pair_short_starts: int = 2
    n_partners: int = 3
    pair_search_from: float = 0.1
    update_max_nfev: int = 30
    jacobian_refresh: int | None = 4
    settled_sigma: float | None = 0.1
    warm_lead_s: float | None = 0.3
    settle_s: float = 2.0
    step_factor: float = 2.5
    solver: str = "integrate"
    reading_contenders: int = 2
    n_bootstrap: int = 200
    random_state: int = 0

    _parameter_constraints = {
        "max_nfev": [Interval(Integral, 1, None, closed="left")],
        "n_probe": [Interval(Integral, 1, None, closed="left")],
        "probes_per_parameter": [Interval(Integral, 1, None, closed="left")],
        "pair_probes_per_parameter": [Interval(Integral, 1, None, closed="left")],
        "short_starts": [Interval(Integral, 1, None, closed="left")],
        "pair_short_starts": [Interval(Integral, 1, None, closed="left")],
        "n_partners": [Interval(Integral, 0, None, closed="left")],
        "pair_search_from": [Interval(Real, 0, None, closed="left")],
        "update_max_nfev": [Interval(Integral, 1, None, closed="left")],
        "jacobian_refresh": [Interval(Integral, 1, None, closed="left"), None],
        "settled_sigma": [Interval(Real, 0, None, closed="neither"), None],
        "warm_lead_s": [Interval(Real, 0, None, closed="left"), None],
        "settle_s": [Interval(Real, 0, None, closed="left")],
        "step_factor": [Interval(Real, 0, 2.8, closed="right")],
        "solver": [StrOptions({"harmonic-balance", "integrate"})],
        "reading_contenders": [Interval(Integral, 0, None, closed="left")],
        "n_bootstrap": [Interval(Integral, 20, None, closed="left")],
        "random_state": [Interval(Integral, 0, None, closed="left")],
    }

    def __post_init__(self):
        validate_parameter_constraints(self._parameter_constraints, asdict(self),
                                       caller_name=type(self).__name__)

    def to_dict(self) -> dict:
        """The budget as plain values (the document's ``settings["budget"]``)."""
        return asdict(self)
