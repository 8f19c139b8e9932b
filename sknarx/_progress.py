"""Progress bars for long phases, shown when the ``sknarx`` logger reports INFO.

The command line sets that level (``--quiet`` lowers it); a library user opts in with
``logging.basicConfig(level=logging.INFO)`` or
``logging.getLogger("sknarx").setLevel(logging.INFO)``. Bars go to stderr, so
output files and piped stdout stay clean.
"""

from __future__ import annotations

import logging
import sys

from tqdm.auto import tqdm

__all__ = ["progress_bar"]


def progress_bar(iterable=None, total=None, desc=None, unit="it"):
    """A tqdm bar (with an ETA) over ``iterable``, silent unless INFO is enabled."""
    enabled = logging.getLogger("sknarx").isEnabledFor(logging.INFO)
    return tqdm(iterable, total=total, desc=desc, unit=unit, disable=not enabled,
                file=sys.stderr, dynamic_ncols=True, leave=False)
