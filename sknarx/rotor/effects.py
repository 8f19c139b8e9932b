"""Physical effects that extend the nominal simulator without touching the integrator.

An effect acts at one (or more) of four places in the data flow:

1. **parameters** -- it changes the nominal :class:`RotorParameters` (e.g. a
   bearing-clearance change);
2. **forces** -- it adds generalised forces through a numba-compiled kernel
   ``kernel(t, phi, omega, alpha, q, v, params, out)`` (e.g. rotor-stator rub);
   the simulator chains the kernels of all active effects into the integrator's
   single hook;
3. **speed** -- it changes the speed profile (e.g. speed fluctuation);
4. **measurement** -- it changes what the probes see after the simulation (e.g.
   slow-roll runout, noise).

A new effect subclasses :class:`Effect` and overrides what it needs; nothing else
changes. The canonical names (``rub``, ``runout``, ...) are used in reports and
JSON.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from numba import njit

from .integrator import no_extra_force
from .parameters import DOF_NAMES

__all__ = [
    "Effect",
    "Rub",
    "ProbeRunout",
    "MeasurementNoise",
    "SpeedFluctuation",
    "ClearanceChange",
    "compose_force_kernels",
]


@dataclass
class EffectContext:
    """What an effect may need to know about the simulator it joins."""

    q_static: np.ndarray  # static equilibrium displacements, m / rad
    dof_index: dict = field(default_factory=lambda: {n: i for i, n in enumerate(DOF_NAMES)})


class Effect:
    """Base class: an effect that does nothing. Override the hooks you need."""

    name = "none"

    def modify_parameters(self, params):
        return params

    def force_kernel(self, context: EffectContext):
        """``(kernel, params_array)`` or ``None``."""
        return None

    def modify_speed(self, t, omega, rng):
        return omega

    def measure(self, table, rng):
        """Change the recorded table (a DataFrame with DOF columns) in place or return a new one."""
        return table

    def __repr__(self):
        fields_ = ", ".join(f"{k}={v!r}" for k, v in vars(self).items())
        return f"{type(self).__name__}({fields_})"


# --------------------------------------------------------------------- forces
@njit(nogil=True, cache=True)
def _rub_kernel(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    ix, iy = int(p[0]), int(p[1])
    x = q[ix] - p[2]
    y = q[iy] - p[3]
    r = math.sqrt(x * x + y * y)
    gap, kr, mu = p[4], p[5], p[6]
    if r > gap:
        fn = kr * (r - gap)
        cx, cy = x / r, y / r
        # normal force inward; Coulomb friction opposing the surface speed of a
        # forward-spinning shaft (tangent direction (-cy, cx))
        out[ix] += -fn * cx + mu * fn * cy
        out[iy] += -fn * cy - mu * fn * cx


@dataclass(repr=False)
class Rub(Effect):
    """Rotor-stator rub at a disk: radial contact beyond a clearance, with friction.

    ``F_n = k_c (r - c)`` for ``r > c`` (``r`` the disk's radial displacement from
    the stator centre, set at the static equilibrium), friction ``mu F_n``
    tangential against the spin. Signature: truncated orbits, 2x/3x and
    sub-synchronous (1/2x) components, strongest where the amplitude peaks.

    Parameters
    ----------
    clearance : float
        Radial rotor-stator gap, m.
    stiffness : float
        Contact stiffness, N/m.
    friction : float
        Coulomb friction coefficient.
    at : str
        Disk, ``'O1'`` or ``'O2'``.
    """

    clearance: float = 5e-4
    stiffness: float = 5e6
    friction: float = 0.1
    at: str = "O1"
    name = "rub"

    def force_kernel(self, context):
        ix, iy = context.dof_index["x" + self.at], context.dof_index["y" + self.at]
        p = np.array([ix, iy, context.q_static[ix], context.q_static[iy], self.clearance,
                      self.stiffness, self.friction], dtype=float)
        return _rub_kernel, p


def compose_force_kernels(kernels):
    """One kernel that calls every ``(kernel, params)`` in turn; params are concatenated."""
    if not kernels:
        return no_extra_force, np.zeros(1)
    funcs = tuple(k for k, _ in kernels)
    sizes = tuple(int(np.size(p)) for _, p in kernels)
    params = np.concatenate([np.asarray(p, dtype=float).ravel() for _, p in kernels])
    return _chain(funcs, sizes), params


@lru_cache(maxsize=64)
def _chain(funcs, sizes):
    if len(funcs) == 1:
        return funcs[0]
    first, n1 = funcs[0], sizes[0]
    rest = _chain(funcs[1:], sizes[1:])

    @njit(nogil=True)
    def chained(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
        first(t, phi, omega, alpha, q, v, p[:n1], out)
        rest(t, phi, omega, alpha, q, v, p[n1:], out)

    return chained


# ----------------------------------------------------------------- parameters
@dataclass(repr=False)
class ClearanceChange(Effect):
    """Bearing radial clearance changed to ``clearance`` (m), e.g. by wear."""

    clearance: float = 5e-6
    name = "clearance"

    def modify_parameters(self, params):
        return params.replace(clearance=self.clearance)


# ---------------------------------------------------------------------- speed
@dataclass(repr=False)
class SpeedFluctuation(Effect):
    """Sinusoidal speed ripple ``omega (1 + a sin(2 pi f t + phase))``."""

    amplitude: float = 0.01
    frequency: float = 1.0
    phase: float = 0.0
    name = "speed-fluctuation"

    def modify_speed(self, t, omega, rng):
        return omega * (1.0 + self.amplitude * np.sin(2 * np.pi * self.frequency * t + self.phase))


# ---------------------------------------------------------------- measurement
@dataclass(repr=False)
class ProbeRunout(Effect):
    """Slow-roll runout: a 1x vector fixed to the shaft, the same at every speed.

    Adds ``A cos(phi + phase)`` to x channels and ``A sin(phi + phase)`` to y
    channels of the probes at ``planes`` (mechanical and electrical runout of the
    probe track). ``phi`` is the shaft angle, so it needs the ``phi`` column.
    """

    amplitude: float = 10e-6
    phase: float = 0.0
    planes: tuple = ("O1",)
    name = "runout"

    def measure(self, table, rng):
        phi = table["phi"].to_numpy()
        for plane in self.planes:
            if "x" + plane in table:
                table["x" + plane] = table["x" + plane] + self.amplitude * np.cos(phi + self.phase)
            if "y" + plane in table:
                table["y" + plane] = table["y" + plane] + self.amplitude * np.sin(phi + self.phase)
        return table


@dataclass(repr=False)
class MeasurementNoise(Effect):
    """White Gaussian noise on every displacement channel at a signal-to-noise ratio (dB)."""

    snr_db: float = 30.0
    name = "noise"

    def measure(self, table, rng):
        for col in DOF_NAMES:
            if col in table:
                x = table[col].to_numpy()
                ac = x - x.mean()
                sigma = math.sqrt(np.mean(ac**2) / 10 ** (self.snr_db / 10.0))
                table[col] = x + sigma * rng.standard_normal(x.shape)
        return table
