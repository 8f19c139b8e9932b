"""Sim-to-real gap diagnosis: where, which unmodelled effect, how far it shrinks.

:func:`diagnose` (time-series sweeps) and
:func:`~sknarx.bode.diagnose_order_domain` (order-tracked Bode records) fit the
effect library on the training speeds and judge each candidate on the held-out ones;
:class:`VerdictRule` holds every value that decides the verdict, :class:`SearchBudget`
how hard the search tries.
"""

from ..orders import order_features
from .budget import SearchBudget
from .candidate import Candidate, NoiseFloor, Shortfall, Verdict
from .gapmap import compare, regions
from .measured import check_measured, load_measured
from .passes import PassComparison, compare_pass_features, compare_passes
from .result import GapDiagnosis
from .rule import ORDER_DOMAIN_RULE, VerdictRule
from .timeseries import LIBRARY, diagnose
from .updating import UpdateResult, UpdatingParameter, update_nominal_model

__all__ = ["diagnose", "GapDiagnosis", "VerdictRule", "SearchBudget", "ORDER_DOMAIN_RULE",
           "Candidate", "Shortfall", "Verdict", "NoiseFloor", "LIBRARY", "order_features",
           "compare", "regions", "load_measured", "check_measured", "update_nominal_model",
           "UpdatingParameter", "UpdateResult", "compare_passes", "compare_pass_features",
           "PassComparison"]
