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
    SimulationInterval,
    SpeedExtrapolationWarning,
    SpeedScheduledNarx,
    correlation_tests,
    free_run_nrmse,
    free_run_scorer,
    nrmse,
    one_step_residuals,
    validity_summary,
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
    "correlation_tests",
    "validity_summary",
    "one_step_residuals",
    "SimulationInterval",
    "model_to_json",
    "model_from_json",
]
