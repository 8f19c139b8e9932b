"""sknarx: speed-scheduled polynomial NARX models of nonlinear rotor-bearing systems.

The four stages of the paper's method are importable from here:
``RotorBearingSimulator`` (the physics simulator), ``NarxTermDictionary``,
``CommonStructureEFOR`` and ``SpeedScheduledNarx``.

Data flow one way: simulator (:mod:`sknarx.rotor`) -> sweep table ->
term dictionary -> common-structure selection -> speed-scheduled model
(:mod:`sknarx.narx`) -> reports.
"""

import logging as _logging

from ._version import __version__
from .io import model_from_json, model_to_json
from .narx import (
    CommonStructureEFOR,
    FreeRunDivergenceError,
    FreeRunDivergenceWarning,
    IllConditionedWarning,
    LeaveOneSpeedOut,
    MultiOutputScheduledNarx,
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
from .rotor import RotorBearingSimulator

# The package logs to "sknarx"; an application decides where that goes (the CLI: stderr).
_logging.getLogger(__name__).addHandler(_logging.NullHandler())

__all__ = [
    "__version__",
    "NarxTermDictionary",
    "CommonStructureEFOR",
    "SpeedScheduledNarx",
    "MultiOutputScheduledNarx",
    "LeaveOneSpeedOut",
    "FreeRunDivergenceError",
    "FreeRunDivergenceWarning",
    "SpeedExtrapolationWarning",
    "IllConditionedWarning",
    "free_run_scorer",
    "free_run_nrmse",
    "nrmse",
    "correlation_tests",
    "validity_summary",
    "one_step_residuals",
    "SimulationInterval",
    "RotorBearingSimulator",
    "model_to_json",
    "model_from_json",
]
