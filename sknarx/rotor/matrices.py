"""Mass, damping, gyroscopic and stiffness matrices of the 12-DOF rotor.

Derivation (details and the reasons for each choice in ``docs/rotor_model.md``):
bending in the x-z plane uses the slope ``dx/dz = ty``, bending in the y-z plane
the slope ``dy/dz = -tx``; both planes share one 6x6 *plane model* over
``(w_A, w_O1, slope_O1, w_O2, slope_O2, w_B)``:

* shaft segment A-O1 (length a1): an Euler-Bernoulli beam pinned in the bearing
  and clamped in disk O1 (a propped cantilever) stores ``k1/2 * d1^2`` with
  ``d1 = w_O1 - w_A - a1 slope_O1`` (its deflection relative to the tangent at
  the disk); likewise O2-B (length b2) with ``k2`` and
  ``d2 = w_B - w_O2 - b2 slope_O2``;
* the bolted joint between the disks (length ``d = a2 - a1``): the shaft
  through it as an Euler-Bernoulli element with lateral stiffness ``k = 12 EI/d^3``,
  in parallel with the contact stiffness ``kb`` on the relative lateral
  displacement and ``k_theta`` on the relative tilt;
* damping: ``c_a, c_b`` at the bearings to ground, ``c_d1, c_d2`` on the relative
  lateral displacement of each disk and its bearing (shaft bending damping; the
  share ``frame_share_d1``, ``frame_share_d2`` of each from the disk to ground),
  ``c_O1 + c_O2`` on the relative lateral displacement of the two disks (the
  bolted joint's interface damping; the share ``tilt_share_O`` of each on its disk's
  tilt to ground instead);
* gyroscopic moments ``J_polar * Omega`` couple the tilts of each disk.

Every element is written as ``stiffness * v v^T`` over a deformation vector ``v``,
so rigid-body motions of the free rotor store no energy by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .parameters import DOF_NAMES, RotorParameters

__all__ = ["RotorMatrices", "assemble", "DOF_INDEX"]

DOF_INDEX = {name: i for i, name in enumerate(DOF_NAMES)}

# Plane coordinates -> global DOF indices, and the sign of the slope mapping.
_X_PLANE = np.array([0, 2, 5, 6, 9, 10])
_Y_PLANE = np.array([1, 3, 4, 7, 8, 11])
_X_SIGN = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
_Y_SIGN = np.array([1.0, 1.0, -1.0, 1.0, -1.0, 1.0])


@dataclass(frozen=True)
class RotorMatrices:
    """``M q'' + (C + Omega G) q' + K q = F`` in SI units, DOF order ``DOF_NAMES``."""

    M: np.ndarray
    C: np.ndarray
    G: np.ndarray
    K: np.ndarray
    gravity_force: np.ndarray  # N (or N m), constant


def _rank1(v, s):
    v = np.asarray(v, dtype=float)
    return s * np.outer(v, v)


def plane_matrices(p: RotorParameters):
    """Mass, damping and stiffness of one bending plane (6x6)."""
    d = p.a2 - p.a1
    K = np.zeros((6, 6))
    K += _rank1([-1, 1, -p.a1, 0, 0, 0], p.k1)
    K += _rank1([0, 0, 0, -1, -p.b2, 1], p.k2)
    K += _rank1([0, -1, -d / 2, 1, -d / 2, 0], p.kb)
    K += _rank1([0, 0, -1, 0, 1, 0], p.k_theta)
    EI = p.k * d**3 / 12.0
    beam = EI / d**3 * np.array(
        [
            [12, 6 * d, -12, 6 * d],
            [6 * d, 4 * d * d, -6 * d, 2 * d * d],
            [-12, -6 * d, 12, -6 * d],
            [6 * d, 2 * d * d, -6 * d, 4 * d * d],
        ]
    )
    K[1:5, 1:5] += beam
    C = np.zeros((6, 6))
    # each disk damper across its segment, but for the share that acts disk to frame
    s1, s2 = p.frame_share_d1, p.frame_share_d2
    C += _rank1([-1, 1, 0, 0, 0, 0], p.c_d1 * (1.0 - s1))
    C += _rank1([0, 0, 0, -1, 0, 1], p.c_d2 * (1.0 - s2))
    C[1, 1] += p.c_d1 * s1
    C[3, 3] += p.c_d2 * s2
    # the bolted joint's interface damping, one share per disk face, but for the share
    # read as damping of each disk's tilt (N m s/rad) to the frame
    t = p.tilt_share_O
    C += _rank1([0, -1, 0, 1, 0, 0], (p.c_O1 + p.c_O2) * (1.0 - t))
    C[2, 2] += p.c_O1 * t
    C[4, 4] += p.c_O2 * t
    C[0, 0] += p.c_a
    C[5, 5] += p.c_b
    M = np.diag([p.m_A, p.m_O1, p.J_diam1, p.m_O2, p.J_diam2, p.m_B])
    return M, C, K


def assemble(p: RotorParameters) -> RotorMatrices:
    """Global 12x12 matrices of the rotor (bearings not included: they are nonlinear)."""
    Mp, Cp, Kp = plane_matrices(p)
    M = np.zeros((12, 12))
    C = np.zeros((12, 12))
    K = np.zeros((12, 12))
    for idx, sign in ((_X_PLANE, _X_SIGN), (_Y_PLANE, _Y_SIGN)):
        S = np.outer(sign, sign)
        M[np.ix_(idx, idx)] += S * Mp
        C[np.ix_(idx, idx)] += S * Cp
        K[np.ix_(idx, idx)] += S * Kp
    G = np.zeros((12, 12))
    for tx, ty, Jp in (("txO1", "tyO1", p.J_polar1), ("txO2", "tyO2", p.J_polar2)):
        i, j = DOF_INDEX[tx], DOF_INDEX[ty]
        G[i, j] = Jp
        G[j, i] = -Jp
    fg = np.zeros(12)
    for name, m in (("yA", p.m_A), ("yO1", p.m_O1), ("yO2", p.m_O2), ("yB", p.m_B)):
        fg[DOF_INDEX[name]] = -m * p.gravity
    return RotorMatrices(M=M, C=C, G=G, K=K, gravity_force=fg)
