"""Bearing housings on pedestals: four more degrees of freedom.

The nominal rotor holds each ball bearing against the frame. With pedestals, each
bearing's outer race sits in a housing of its own mass on a pedestal (stiffness and
damping per direction, to the frame); the Hertzian contact and the bearing damper
(``c_a``, ``c_b``) act between journal and housing. The contact stays nonlinear: the
integrator evaluates it on the journal's displacement relative to its housing, so a
soft pedestal changes what the contact carries over each revolution (it unloads and
stiffens as the journal orbits), which no linearisation about the static sag gives.

DOF order: the rotor's 12 (``DOF_NAMES``), then ``HOUSING_NAMES``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .matrices import DOF_INDEX, RotorMatrices

__all__ = ["HOUSING_NAMES", "JOURNAL_OF", "Pedestals", "bearing_dofs", "with_pedestals"]

#: housing displacements (m) appended after the rotor's DOFs
HOUSING_NAMES = ("xHA", "yHA", "xHB", "yHB")
#: each housing DOF's journal DOF (the same bearing and direction)
JOURNAL_OF = dict(zip(HOUSING_NAMES, ("xA", "yA", "xB", "yB"), strict=True))

_JOURNALS = ((DOF_INDEX["xA"], DOF_INDEX["yA"]), (DOF_INDEX["xB"], DOF_INDEX["yB"]))


@dataclass(frozen=True)
class Pedestals:
    """Both bearings' housings: ``mass`` (kg, each), pedestal ``stiffness`` (N/m) and
    ``damping`` (N s/m), each an ``(x, y)`` pair acting housing to frame."""

    mass: float
    stiffness: tuple
    damping: tuple

    def __post_init__(self):
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"A bearing housing has mass: got {self.mass!r} kg (must be > 0).")
        for label, pair in (("stiffness", self.stiffness), ("damping", self.damping)):
            vals = np.asarray(pair, dtype=float)
            if vals.shape != (2,) or not np.all(np.isfinite(vals)) or np.any(vals < 0):
                raise ValueError(f"Pedestal {label} must be two finite non-negative values "
                                 f"(x, y); got {pair!r}.")
        if min(self.stiffness) <= 0:
            raise ValueError(f"Pedestal stiffness must be positive (N/m); got {self.stiffness!r}.")


def bearing_dofs(n_dof):
    """Per bearing (A, B): the journal's ``(x, y)`` DOF indices and its housing's, or
    ``(-1, -1)`` when the bearing is held by the frame (12 DOF)."""
    if n_dof == len(DOF_INDEX):
        return [(j, (-1, -1)) for j in _JOURNALS]
    if n_dof == len(DOF_INDEX) + len(HOUSING_NAMES):
        base = len(DOF_INDEX)
        return [(j, (base + 2 * b, base + 2 * b + 1)) for b, j in enumerate(_JOURNALS)]
    raise ValueError(f"A rotor has {len(DOF_INDEX)} DOF, or {len(DOF_INDEX) + 4} with "
                     f"pedestals; got {n_dof}.")


def with_pedestals(m: RotorMatrices, params, pedestals: Pedestals) -> RotorMatrices:
    """The rotor's matrices with both housings added (16 DOF).

    The bearing dampers move from journal-to-frame to journal-to-housing; each housing
    carries its own weight to its pedestal.
    """
    n = m.M.shape[0]
    N = n + len(HOUSING_NAMES)
    M, C, G, K = (np.zeros((N, N)) for _ in range(4))
    for big, small in ((M, m.M), (C, m.C), (G, m.G), (K, m.K)):
        big[:n, :n] = small
    fg = np.zeros(N)
    fg[:n] = m.gravity_force
    dampers = (params.c_a, params.c_b)
    for (journal, housing), ca in zip(bearing_dofs(N), dampers, strict=True):
        for d, (j, h) in enumerate(zip(journal, housing, strict=True)):
            # c_a sat between journal and frame; now between journal and housing
            C[h, h] += ca
            C[j, h] -= ca
            C[h, j] -= ca
            M[h, h] = pedestals.mass
            K[h, h] += pedestals.stiffness[d]
            C[h, h] += pedestals.damping[d]
        fg[housing[1]] = -pedestals.mass * params.gravity
    return RotorMatrices(M=M, C=C, G=G, K=K, gravity_force=fg)
