"""Linearised rotor: natural frequencies, Campbell diagram, critical speeds, unbalance response.

The ball bearings are linearised about the static (gravity) equilibrium: their
2x2 stiffness is the Jacobian of the Hertzian force averaged over one ball pitch
of cage rotation, which removes the ball-passage modulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import scipy.linalg as sla
from numba import njit
from scipy.optimize import brentq

from .bearings import bearing_force
from .matrices import DOF_INDEX

__all__ = ["LinearRotorModel", "bearing_stiffness"]


def bearing_stiffness(x, y, params, n_avg: int = 16, rel_step: float = 1e-3, which="A"):
    """Averaged 2x2 tangent stiffness ``-dF/dq`` (N/m) of bearing ``which`` (``'A'`` or
    ``'B'``) at (x, y)."""
    kB, clearance = params.bearing(which)
    h = rel_step * max(abs(x), abs(y), clearance, 1e-7)
    pitch = 2 * np.pi / params.n_balls / params.cage_ratio  # shaft angle of one ball pitch
    # one compiled loop: a simulator is built at every evaluation of a calibration, and
    # the same central differences called force by force from Python were a tenth of it
    return _averaged_stiffness(float(x), float(y), float(h), float(pitch), int(n_avg),
                               float(kB), float(clearance), float(params.hertz_exponent),
                               int(params.n_balls), float(params.cage_ratio))


@njit(cache=True, nogil=True)
def _averaged_stiffness(x, y, h, pitch, n_avg, kB, gamma, expo, n_balls,
                        cage_ratio):  # pragma: no cover - compiled
    """Central differences of the force at ``n_avg`` shaft angles over one ball pitch,
    averaged (the angles and the order of the sums as the Python loop over
    ``np.linspace(0, pitch, n_avg, endpoint=False)`` had them: the same numbers)."""
    Kb = np.zeros((2, 2))
    for i in range(n_avg):
        phi = i * (pitch / n_avg)
        for j in range(2):
            dx = h if j == 0 else 0.0
            dy = h if j == 1 else 0.0
            fpx, fpy = bearing_force(x + dx, y + dy, phi, kB, gamma, expo, n_balls,
                                     cage_ratio)
            fmx, fmy = bearing_force(x - dx, y - dy, phi, kB, gamma, expo, n_balls,
                                     cage_ratio)
            Kb[0, j] -= (fpx - fmx) / (2 * h)
            Kb[1, j] -= (fpy - fmy) / (2 * h)
    return Kb / n_avg


def _oscillatory(lam):
    """The eigenvalues of oscillatory modes, one of each conjugate pair (positive
    frequency): what :meth:`LinearRotorModel.eigen` returns and the step limit reads."""
    return lam.imag > 1e-9


@dataclass
class LinearRotorModel:
    """``M q'' + (C + Omega G) q' + K q = F`` with the bearings linearised.

    Attributes
    ----------
    M, C, G, K : ndarray (12, 12)
    unbalance : ndarray (12,) complex
        Unbalance force per unit ``Omega^2`` (N s^2), phasor convention
        ``F(t) = Re(F e^{i Omega t})``.
    """

    M: np.ndarray
    C: np.ndarray
    G: np.ndarray
    K: np.ndarray
    unbalance: np.ndarray

    def state_matrix(self, omega: float) -> np.ndarray:
        """First-order state matrix at speed ``omega`` (rad/s), states ``(q, q')``."""
        n = self.M.shape[0]
        Minv = np.linalg.inv(self.M)
        return np.block(
            [[np.zeros((n, n)), np.eye(n)],
             [-Minv @ self.K, -Minv @ (self.C + omega * self.G)]]
        )

    def max_oscillatory_eigenvalue(self, omega: float) -> float:
        """Largest ``|lambda|`` of the oscillatory modes (those :meth:`eigen` returns) at
        ``omega`` (rad/s): the integration step's stability limit, without the vectors."""
        lam = sla.eigvals(self.state_matrix(omega))
        return float(np.max(np.abs(lam[_oscillatory(lam)])))

    def eigen(self, omega: float):
        """Eigenvalues and eigenvectors of the state matrix at speed ``omega`` (rad/s)."""
        n = self.M.shape[0]
        lam, vec = sla.eig(self.state_matrix(omega))
        keep = _oscillatory(lam)
        lam, vec = lam[keep], vec[:n, keep]
        order = np.argsort(lam.imag)
        return lam[order], vec[:, order]

    def modes(self, omega: float) -> pd.DataFrame:
        """Damped natural frequencies (rad/s), damping ratios and whirl direction."""
        lam, vec = self.eigen(omega)
        whirl = []
        for v in vec.T:
            # x = Re(X e^{i w t}), y = Re(Y e^{i w t}); forward (x -> y) when Y = -i X,
            # i.e. Im(conj(X) Y) < 0, summed over the translational stations.
            s = sum(np.imag(np.conj(v[DOF_INDEX["x" + st]]) * v[DOF_INDEX["y" + st]])
                    for st in ("A", "O1", "O2", "B"))
            whirl.append("forward" if s < 0 else "backward")
        return pd.DataFrame(
            {
                "frequency": lam.imag,
                "damping_ratio": -lam.real / np.abs(lam),
                "whirl": whirl,
            }
        )

    def campbell(self, speeds, n_modes: int = 6) -> pd.DataFrame:
        """Long table: speed, mode number, frequency (rad/s), damping ratio, whirl."""
        rows = []
        for w in np.asarray(speeds, dtype=float):
            m = self.modes(w).iloc[:n_modes]
            for i, r in enumerate(m.itertuples()):
                rows.append((w, i, r.frequency, r.damping_ratio, r.whirl))
        return pd.DataFrame(rows, columns=["speed", "mode", "frequency", "damping_ratio",
                                           "whirl"])

    def critical_speeds(self, max_speed: float = 2000.0, whirl: str = "forward",
                        n_grid: int = 400) -> np.ndarray:
        """Speeds (rad/s) where a mode of the given whirl crosses the 1x line."""
        grid = np.linspace(1.0, max_speed, n_grid)
        found = []
        n_modes = 8

        def mode_freqs(w):
            m = self.modes(w)
            m = m[m.whirl == whirl].frequency.to_numpy()
            return np.pad(m[:n_modes], (0, max(0, n_modes - m[:n_modes].size)),
                          constant_values=np.inf)

        prev = mode_freqs(grid[0]) - grid[0]
        for a, b in zip(grid[:-1], grid[1:], strict=True):
            cur = mode_freqs(b) - b
            for i in range(n_modes):
                if np.isfinite(prev[i]) and np.isfinite(cur[i]) and prev[i] > 0 >= cur[i]:
                    found.append(brentq(lambda w, i=i: mode_freqs(w)[i] - w, a, b, xtol=1e-10))
            prev = cur
        return np.array(sorted(found))

    def unbalance_response(self, speeds, dof: str = "xO1") -> pd.DataFrame:
        """Steady linear response amplitude (m, 0-peak) and phase (rad) of ``dof``."""
        idx = DOF_INDEX[dof]
        amp, phase = [], []
        for w in np.asarray(speeds, dtype=float):
            D = self.K - w * w * self.M + 1j * w * (self.C + w * self.G)
            X = np.linalg.solve(D, w * w * self.unbalance)
            amp.append(abs(X[idx]))
            phase.append(np.angle(X[idx]))
        return pd.DataFrame({"speed": speeds, "amplitude": amp, "phase": phase})
