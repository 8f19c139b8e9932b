"""End-to-end reproduction of the paper's Case 1 (``sknarx paper``)."""

from .case import PaperCase
from .study import Study, run_study

__all__ = ["PaperCase", "Study", "run_study"]
