"""Sim-to-real gap diagnosis: where, which unmodelled effect, how far it shrinks."""

from .diagnosis import LIBRARY, DiagnosisSettings, diagnose
from .features import order_features
from .gapmap import compare, regions
from .measured import check_measured, load_measured

__all__ = ["diagnose", "DiagnosisSettings", "LIBRARY", "order_features", "compare", "regions",
           "load_measured", "check_measured"]
