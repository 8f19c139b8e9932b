"""NARX identification: term dictionary, common-structure selection, speed scheduling."""

from .dictionary import NarxTermDictionary
from .freerun import FreeRunDivergenceError
from .scheduling import SpeedExtrapolationWarning, SpeedScheduledNarx
from .scoring import free_run_nrmse, free_run_scorer, nrmse
from .selection import CommonStructureEFOR, IllConditionedWarning
from .splitters import LeaveOneSpeedOut
from .terms import monomial_exponents, n_candidate_terms, parse_terms, term_names

__all__ = [
    "NarxTermDictionary",
    "CommonStructureEFOR",
    "SpeedScheduledNarx",
    "LeaveOneSpeedOut",
    "FreeRunDivergenceError",
    "SpeedExtrapolationWarning",
    "IllConditionedWarning",
    "free_run_scorer",
    "free_run_nrmse",
    "nrmse",
    "monomial_exponents",
    "n_candidate_terms",
    "parse_terms",
    "term_names",
]
