"""sknarx: speed-scheduled polynomial NARX models of nonlinear rotor-bearing systems.

Data flow one way: simulator (:mod:`sknarx.rotor`) -> sweep table ->
term dictionary -> common-structure selection -> speed-scheduled model
(:mod:`sknarx.narx`) -> reports.
"""

from ._version import __version__
from .io import model_from_json, model_to_json
from .narx import (
    CommonStructureEFOR,
    FreeRunDivergenceError,
    IllConditionedWarning,
    LeaveOneSpeedOut,
    NarxTermDictionary,
    SpeedExtrapolationWarning,
    SpeedScheduledNarx,
    free_run_nrmse,
    free_run_scorer,
    nrmse,
)

__all__ = [
    "__version__",
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
    "model_to_json",
    "model_from_json",
]
