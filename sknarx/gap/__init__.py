"""Sim-to-real gap diagnosis: where, which unmodelled effect, how far it shrinks."""

from .diagnosis import LIBRARY, DiagnosisSettings, diagnose
from .features import order_features
from .gapmap import compare, regions
from .measured import check_measured, load_measured
from .passes import PassComparison, compare_pass_features, compare_passes
from .result import GapDiagnosis
from .updating import UpdateResult, UpdatingParameter, update_nominal_model

__all__ = ["diagnose", "GapDiagnosis", "DiagnosisSettings", "LIBRARY", "order_features",
           "compare", "regions", "load_measured", "check_measured", "update_nominal_model",
           "UpdatingParameter", "UpdateResult", "compare_passes", "compare_pass_features",
           "PassComparison"]
