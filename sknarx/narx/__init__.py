"""NARX identification: term dictionary, common-structure selection, speed scheduling."""

from .dictionary import NarxTermDictionary
from .freerun import FreeRunDivergenceError
from .multioutput import MultiOutputScheduledNarx
from .scheduling import SimulationInterval, SpeedExtrapolationWarning, SpeedScheduledNarx
from .scoring import FreeRunDivergenceWarning, free_run_nrmse, free_run_scorer, nrmse
from .selection import CommonStructureEFOR, IllConditionedWarning
from .splitters import LeaveOneSpeedOut
from .terms import monomial_exponents, n_candidate_terms, parse_terms, term_names
from .validity import correlation_tests, one_step_residuals, validity_summary

__all__ = [
    "NarxTermDictionary",
    "CommonStructureEFOR",
    "SpeedScheduledNarx",
    "MultiOutputScheduledNarx",
    "SimulationInterval",
    "LeaveOneSpeedOut",
    "FreeRunDivergenceError",
    "FreeRunDivergenceWarning",
    "SpeedExtrapolationWarning",
    "IllConditionedWarning",
    "free_run_scorer",
    "free_run_nrmse",
    "nrmse",
    "monomial_exponents",
    "n_candidate_terms",
    "parse_terms",
    "term_names",
    "correlation_tests",
    "validity_summary",
    "one_step_residuals",
]
