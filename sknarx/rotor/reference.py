"""The same equations of motion as a vectorised-NumPy right-hand side for SciPy.

Used as an independent cross-check of the compiled integrator (accuracy test)
and as the ``solve_ivp`` peer of the simulator's speed benchmark. Constant speed
only; effects are not included.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["numpy_rhs", "solve_reference"]


def numpy_rhs(sim, omega: float):
    """``f(t, z)`` for ``z = [q, v]`` at constant speed; ``phi = omega t``."""
    p, m = sim.effective_params, sim.matrices
    minv = 1.0 / np.diag(m.M)
    D = m.C + omega * m.G
    K = m.K
    fg = m.gravity_force
    nb = int(p.n_balls)
    pitch = 2 * np.pi * np.arange(nb) / nb
    me1, me2 = p.m_O1 * p.e, p.m_O2 * p.resolved("e_O2")

    def bearing(x, y, phi, which):
        kB, clearance = p.bearing(which)
        th = pitch + p.cage_ratio * phi
        c, s = np.cos(th), np.sin(th)
        d = x * c + y * s - clearance
        f = kB * np.where(d > 0, d, 0.0) ** p.hertz_exponent
        return -(f * c).sum(), -(f * s).sum()

    def rhs(t, z):
        q, v = z[:12], z[12:]
        phi = omega * t + p.unbalance_phase
        f = fg.copy()
        w2 = omega * omega
        f[2] += me1 * w2 * np.cos(phi)
        f[3] += me1 * w2 * np.sin(phi)
        f[6] += me2 * w2 * np.cos(phi + p.beta)
        f[7] += me2 * w2 * np.sin(phi + p.beta)
        for ix, iy, which in ((0, 1, "A"), (10, 11, "B")):
            fbx, fby = bearing(q[ix], q[iy], omega * t, which)
            f[ix] += fbx
            f[iy] += fby
        a = minv * (f - D @ v - K @ q)
        return np.concatenate([v, a])

    return rhs


def solve_reference(sim, omega, t_end, fs, method="DOP853", rtol=1e-10, atol=None, t0=0.0):
    """Solve from the static equilibrium at rest (shaft angle ``omega t``) with SciPy.

    Returns the displacements sampled at ``t0 + k / fs`` and the solver's
    ``OdeResult`` (for its ``nfev``).
    """
    z0 = np.concatenate([sim.static_equilibrium(), np.zeros(12)])
    if atol is None:
        atol = rtol * 1e-3  # displacements are ~1e-4..1e-3 m
    n = int(round((t_end - t0) * fs)) + 1
    t_eval = t0 + np.arange(n) / fs
    sol = solve_ivp(numpy_rhs(sim, omega), (t0, t_eval[-1]), z0, method=method, rtol=rtol,
                    atol=atol, t_eval=t_eval)
    if not sol.success:
        raise RuntimeError(f"solve_ivp failed: {sol.message}")
    return sol.y[:12].T, sol
