"""What the search fits and the verdict judges: typed candidates, shortfalls, verdicts."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["Candidate", "Shortfall", "Verdict", "NoiseFloor", "candidate_label", "percent"]


def percent(share) -> str:
    """A share as a whole per cent; one short of a whole is never rounded up to it
    ('99.6 %', '>99.9 %', not '100 %').

    Examples
    --------
    >>> percent(0.6), percent(0.996), percent(0.9999999988), percent(None)
    ('60 %', '99.6 %', '>99.9 %', '-')
    """
    if share is None or not np.isfinite(float(share)):
        return "-"
    value = 100.0 * float(share)
    text = f"{value:.0f} %"
    if 99.5 <= abs(value) < 100.0:
        text = f"{value:.1f} %" if abs(value) < 99.95 else ">99.9 %"
    return text


def candidate_label(effects) -> str | list:
    """How a candidate is named in the document: an effect's name, a pair's two names, or
    ``[]`` for model error alone."""
    effects = tuple(effects)
    return effects[0] if len(effects) == 1 else list(effects)


@dataclass(eq=False)
class Candidate:
    """One fitted candidate: a single effect, a pair, or model error alone (no effect).

    A front end fits it on the training speeds and compares it on the held-out ones;
    :func:`sknarx.gap.search.rank` sets the held-out excess before any candidate
    (``heldout_before``) and the breadth of its gain (``log_shrink``).

    Parameters
    ----------
    effects : tuple of str
        The effects the candidate adds to the calibrated nominal model; ``()`` where a
        member's linear form replaced it (model error, see ``details["model_error"]``).
    params : dict or list of dict
        Fitted effect parameters in SI units (a pair: one dict per member).
    params_std : dict
        Their standard errors, by ``"effect.parameter"``.
    n_params : int
        Parameters the candidate adds to the calibrated nominal model (the AIC penalty).
    heldout_after : float
        Held-out excess after the fit (dimensionless; ``inf`` where the fitted model
        diverged at a held-out speed).
    cmp : DataFrame or None
        The held-out comparison table of the fit (None where it diverged).
    details : dict
        Front-end entries for the ranking (nuisances, evidence, discrete settings,
        model error, linear-form tests, rotor reading).
    state : object
        The front end's own fit, for warm starts.
    """

    effects: tuple
    params: Any
    params_std: dict
    n_params: int
    heldout_after: float
    cmp: pd.DataFrame | None
    details: dict = field(default_factory=dict)
    state: Any = None
    heldout_before: float = float("nan")
    log_shrink: float = float("nan")
    #: each discrete setting's fit (a crack's station, a rub's disk), best first, by
    #: setting: what a pair member's refit and the verdict's recheck read
    settings_tried: dict = field(default_factory=dict, repr=False)

    @property
    def label(self):
        """The document's name of the candidate (:func:`candidate_label`)."""
        return candidate_label(self.effects)

    @property
    def shrink(self) -> float:
        """Share of the held-out excess removed (0 where there was none)."""
        before = self.heldout_before
        return float(1.0 - self.heldout_after / before) if before > 0 else 0.0

    @property
    def score(self) -> float:
        """Held-out excess plus two per added parameter: an AIC on the chi-square scale."""
        return self.heldout_after + 2.0 * self.n_params

    def shrink_above(self, noise: NoiseFloor | None, n_features: int) -> float:
        """Share of the held-out excess *above the noise* removed,
        ``(E0 - E) / (E0 - n m0)``: no candidate removes the noise, so near the floor
        the plain share would ask an effect to remove some of it too. The plain share
        where the gap is not above the noise or ``noise`` is None."""
        if noise is None:
            return self.shrink
        above = self.heldout_before - noise.median * n_features
        if not above > 0:
            return self.shrink
        return float((self.heldout_before - self.heldout_after) / above)

    def to_entry(self, noise: NoiseFloor | None = None, n_features: int = 1) -> dict:
        """The candidate's ``ranking`` entry in ``diagnosis.json``."""
        out = {"effect": self.label, "params": self.params, "params_std": self.params_std,
               "heldout_gap_before": self.heldout_before,
               "heldout_gap_after": self.heldout_after, "shrink": self.shrink,
               "log_shrink": self.log_shrink, "score": self.score, **self.details}
        if noise is not None:
            out["shrink_above_noise"] = self.shrink_above(noise, n_features)
        return out


@dataclass(frozen=True)
class NoiseFloor:
    """What measurement noise alone leaves of the held-out gap, per feature.

    From :func:`sknarx.gap.floor.noise_floor`: the held-out comparison repeated with
    the calibrated model's own features plus noise drawn at the measured standard
    errors. ``floor`` is the ``1 - false_alarm`` quantile of the held-out excess per
    feature (below it a sweep is within noise), ``median`` its median (what no
    candidate can remove), over ``n_draws`` draws.
    """

    floor: float
    median: float
    n_draws: int
    false_alarm: float

    def to_dict(self) -> dict:
        """The document's ``gap_before["floor"]`` entry."""
        return {"floor_per_feature": self.floor, "noise_per_feature": self.median,
                "n_draws": self.n_draws, "false_alarm": self.false_alarm,
                "rule": "quantile of the held-out excess per feature when the "
                        "calibrated model is compared with itself plus noise drawn at "
                        "the measured standard errors"}


#: each test's sentence: what the judged value is, what the rule asks (format fields
#: ``value`` and ``required``; shares as ``value_pct``, ``required_pct``), and the rule's
#: parameter behind it
TESTS = {
    "shrink": ("removes {value_pct} of the held-out gap above the noise; the rule asks at "
               "least {required_pct}", "min_shrink"),
    "breadth": ("removes {value_pct} of the gap's logarithm (how broadly it fits); the rule "
                "asks at least {required_pct}", "min_log_shrink"),
    "linear-form": ("removes {value_pct} of what its linear form (a change of the linear "
                    "rotor, model error) leaves; the rule asks at least {required_pct}",
                    "min_gain"),
    "pair-trigger": ("the best single leaves {value:.3g} held-out excess per feature, not "
                     "more than the {required:.3g} above which a pair may be named",
                     "pair_trigger"),
    "rival": ("each member alone removes at least {value_pct} of the gap above the noise, "
              "as a named effect must ({required_pct}): two readings of one signature, "
              "not two effects", "min_shrink"),
}


@dataclass(frozen=True)
class Shortfall:
    """One test of the verdict rule a candidate fails (or, for a pair set aside, the
    test that set it aside): the test's name (a key of :data:`TESTS`), the judged value
    and what the rule asks."""

    test: str
    value: float
    required: float

    @property
    def parameter(self) -> str:
        """The :class:`~sknarx.gap.VerdictRule` parameter the test applies."""
        return TESTS[self.test][1]

    def sentence(self) -> str:
        """The test as a sentence, made from the same numbers that decided it."""
        return TESTS[self.test][0].format(
            value=self.value, required=self.required, value_pct=percent(self.value),
            required_pct=percent(self.required))

    def to_dict(self) -> dict:
        """The shortfall as the document states it, with its sentence."""
        return {"test": self.test, "value": self.value, "required": self.required,
                "parameter": self.parameter, "sentence": self.sentence()}


@dataclass
class Verdict:
    """The verdict rule's answer (:meth:`sknarx.gap.VerdictRule.decide`).

    ``outcome`` is ``"no-gap"``, ``"effect"`` or ``"unexplained"``. ``candidate`` is the
    named candidate (an effect, or model error alone for a ``no-gap`` reached that way),
    or for ``unexplained`` and ``no-gap`` the candidate the rule judged and passed over,
    with the tests it failed in ``shortfalls``. ``set_aside`` holds each pair the rule
    would otherwise have judged, with the test that set it aside. ``within_floor``: the
    gap before any candidate was within the no-gap floor.
    """

    outcome: str
    candidate: Candidate | None
    shortfalls: list
    set_aside: list
    within_floor: bool
    e0: float
    floor: NoiseFloor | None

    @property
    def name(self):
        """What the document calls the verdict: ``"no-gap"``, ``"unexplained"``, an
        effect's name or a pair's two names."""
        if self.outcome != "effect":
            return self.outcome
        return self.candidate.label

    @property
    def named(self) -> Candidate | None:
        """The candidate the verdict names (an effect, or model error alone), or None."""
        return self.candidate if not self.shortfalls and self.candidate is not None \
            and self.outcome in ("effect", "no-gap") else None


def finite_or_none(value):
    """A float for a document, None for a value that is not finite."""
    value = float(value)
    return value if np.isfinite(value) else None
