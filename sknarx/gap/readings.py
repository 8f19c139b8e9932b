"""Readings of the nominal rotor: discrete model-form alternatives the data choose.

A paper rotor leaves some of its model open -- where a damper acts, what a stiffness
joins -- and a second engineer reads it the other way. A continuous share between two
readings belongs in the nominal update (:mod:`sknarx.gap.updating`), but an update fitted
on the steady 1x before any effect is fitted takes an effect's own 1x as evidence for
the share: a loose joint's 1x, for instance, pins the share of the joint's dampers on
the joint interface, and the looseness is then fitted in a rotor that cannot open the
way the plant's does. So each alternative reading is also a discrete setting of the
rotor every contender is fitted in, as a crack's station is of the crack: the nominal
update is started (and its prior centred) at the reading, the nuisance-only model and
the leading candidates are fitted in it, and the held-out speeds choose among every
fit of every reading. The reading a verdict was fitted in is model error and is
reported as such; a reading alone (no effect) that explains the gap is a ``no-gap``
verdict with that model error.

Every fit is compared against the same measured features and the same model-form
tolerance (the nominal rotor as given's): the held-out excesses of two readings are
then on one scale, as two stations' are.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields

from ..rotor import RotorParameters

__all__ = ["check_readings", "reading_contenders"]


def check_readings(readings, base: RotorParameters | None = None) -> dict[str, dict]:
    """``readings`` as ``{label: {field: value}}``, checked before any work: each label a
    non-empty string, each change a :class:`~sknarx.rotor.RotorParameters` field set to a
    number that makes ``base`` (the paper's rotor by default) a physical rotor (its own
    validation). None or empty: no alternative reading."""
    if not readings:
        return {}
    if not isinstance(readings, Mapping):
        raise ValueError("readings must map a label to the rotor parameters it changes, "
                         "e.g. {'dampers on the disks' tilt': {'tilt_share_O': 1.0}}; "
                         f"got {type(readings).__name__}.")
    known = {f.name for f in fields(RotorParameters)}
    out = {}
    for label, changes in readings.items():
        if not isinstance(label, str) or not label.strip():
            raise ValueError(f"A reading's label must be a non-empty string, not {label!r}.")
        if not isinstance(changes, Mapping) or not changes:
            raise ValueError(f"Reading {label!r} must change at least one rotor parameter "
                             "({parameter: value}).")
        unknown = sorted(set(changes) - known)
        if unknown:
            raise ValueError(f"Reading {label!r} changes unknown rotor parameter(s) "
                             f"{unknown}; the rotor's parameters are those of "
                             "RotorParameters (docs/rotor_model.md).")
        bad = [k for k, v in changes.items()
               if isinstance(v, bool) or not isinstance(v, (int, float))]
        if bad:
            raise ValueError(f"Reading {label!r} sets {bad} to a non-number; give each "
                             "parameter its value in SI units.")
        out[label] = {k: float(v) for k, v in changes.items()}
        try:
            (base or RotorParameters()).replace(**out[label])
        except ValueError as exc:
            raise ValueError(f"Reading {label!r} is not a rotor: {exc}") from exc
    return out


def reading_contenders(ranking: list, k: int) -> tuple:
    """The effects of the ``k`` best single candidates of ``ranking`` (candidates or
    their document entries; model error alone and pairs aside): those fitted again in
    every other reading. A pair of them is formed by the search in that reading where
    its lead leaves a gap."""
    out = []
    for r in ranking:
        e = r["effect"] if isinstance(r, dict) else r.label
        if isinstance(e, str) and e not in out:
            out.append(e)
        if len(out) == k:
            break
    return tuple(out)
