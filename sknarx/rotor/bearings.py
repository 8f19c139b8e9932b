"""Hertzian ball-bearing force with radial clearance and cage rotation (paper, Eq. 1).

Ball ``j`` sits at angle ``theta_j = 2 pi j / Nb + (r / (R + r)) phi`` where ``phi``
is the shaft's rotation angle (``omega t`` at constant speed), so the balls
orbit with the cage. Its deflection is ``delta_j = x cos theta_j + y sin theta_j
- gamma``; a compressed ball (``delta_j > 0``) pushes the journal back with
``kB delta_j^m`` along ``-(cos theta_j, sin theta_j)``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["bearing_force", "bearing_force_py"]


@njit(cache=True, nogil=True, inline="always")
def bearing_force(x, y, phi, kB, gamma, expo, n_balls, cage_ratio):  # pragma: no cover
    """Force (fx, fy) in N on the journal at (x, y) m; ``phi`` is the shaft angle."""
    c, s = cage_angle(phi, cage_ratio)
    cs, ss = ball_pitch(n_balls)
    return bearing_force_at(x, y, c, s, cs, ss, kB, gamma, expo, n_balls)


@njit(cache=True, nogil=True, inline="always")
def cage_angle(phi, cage_ratio):  # pragma: no cover
    """(cos, sin) of the first ball's angle, the cage's, at shaft angle ``phi``."""
    th0 = cage_ratio * phi
    return math.cos(th0), math.sin(th0)


@njit(cache=True, nogil=True, inline="always")
def ball_pitch(n_balls):  # pragma: no cover
    """(cos, sin) of the angle between neighbouring balls."""
    step = 2.0 * math.pi / n_balls
    return math.cos(step), math.sin(step)


@njit(cache=True, nogil=True, inline="always")
def bearing_force_at(x, y, c, s, cs, ss, kB, gamma, expo, n_balls):  # pragma: no cover
    """:func:`bearing_force` from the cage angle's (cos, sin) ``(c, s)`` and the ball
    pitch's ``(cs, ss)``: an integrator computes the pitch once per run and the cage
    angle once per shaft angle, shared by both bearings and by the RK-4 stages that
    evaluate the same instant, and gets the same forces bit for bit."""
    fx = 0.0
    fy = 0.0
    for _ in range(n_balls):
        d = x * c + y * s - gamma
        if d > 0.0:
            f = kB * d * math.sqrt(d) if expo == 1.5 else kB * d**expo
            fx -= f * c
            fy -= f * s
        # rotate (c, s) by one ball pitch: one sincos per bearing, not per ball
        c, s = c * cs - s * ss, s * cs + c * ss
    return fx, fy


def bearing_force_py(x, y, phi, params, which="A"):
    """Python-side evaluation (static equilibrium, linearisation, tests) of bearing
    ``which`` (``'A'`` or ``'B'``: each has its own contact stiffness and clearance)."""
    kB, clearance = params.bearing(which)
    return np.array(
        bearing_force(
            float(x), float(y), float(phi), kB, clearance,
            params.hertz_exponent, int(params.n_balls), params.cage_ratio,
        )
    )
