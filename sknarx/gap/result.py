"""What a gap diagnosis returns: the JSON document and the arrays behind its figures."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["GapDiagnosis"]


@dataclass
class GapDiagnosis(Mapping):
    """Result of a gap diagnosis, from either measurement front end.

    Reads like the ``diagnosis.json`` document (``result["verdict"]``,
    ``result["ranking"]``, ...: see ``docs/gap.md`` for every key); the arrays that
    figures and reports are drawn from ride along as attributes and are not part of the
    document. Nothing is written by the diagnosis: the caller writes the report
    (:func:`sknarx.gap.report.write_gap_outputs`,
    :func:`sknarx.bode.write_bode_outputs`).

    Parameters
    ----------
    document : dict
        The JSON-able result: ``verdict``, ``ranking``, ``where``, ``shrink`` and the
        front end's details.
    front_end : {"time-series", "order-domain"}
        The measurement front end that produced it.
    tables : dict of DataFrame
        Feature-by-feature comparison tables (``before``, ``all``, ``after``): speed in
        rad/s, gap in m, ``z2`` and ``excess`` dimensionless.
    base : object, optional
        The nominal rotor the effects were fitted on: the updated
        :class:`~sknarx.rotor.RotorParameters` of a time-series diagnosis, the linear
        rotor with its calibrated bearings of an order-domain one.
    curves : dict
        Front-end arrays for figures (the order-domain front end: the binned record and
        the nominal, calibrated and corrected 1x curves, in m).
    verdict : Verdict, optional
        The verdict rule's typed answer (:class:`~sknarx.gap.candidate.Verdict`): the
        named or judged candidate and the tests it failed.

    Examples
    --------
    >>> from sknarx.gap.result import GapDiagnosis
    >>> r = GapDiagnosis({"verdict": "no-gap", "shrink": 0.0}, front_end="time-series")
    >>> r["verdict"], sorted(r)
    ('no-gap', ['shrink', 'verdict'])
    """

    document: dict
    front_end: str
    tables: dict = field(default_factory=dict)
    base: Any = None
    curves: dict = field(default_factory=dict)
    verdict: Any = None

    def __getitem__(self, key: str):
        return self.document[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.document)

    def __len__(self) -> int:
        return len(self.document)

    def __repr__(self) -> str:
        shrink = self.document.get("shrink")
        return (f"GapDiagnosis(front_end={self.front_end!r}, verdict="
                f"{self.document.get('verdict')!r}, shrink={shrink!r})")
