"""Order tracking of a simulated run-up of a linear rotor (constant angular acceleration).

A run-up is not a sequence of steady states: near a lightly damped critical speed
the rotor needs ``~Q`` revolutions to build its resonant response, so at a few
hundred rpm/s the tracked 1x peak is lower, later and followed by a beat (free
vibration at the natural frequency against the 1x) that shows up as dips and
secondary peaks in a Bode plot -- a pattern easily mistaken for a split critical.
This module simulates that, for comparison with measured order-tracked run-ups.

Method. The rotor's finite-element model is reduced to its lowest undamped modes;
in state space ``s' = A s + B f(t)`` is diagonalised (``A = V diag(lam) V^-1``)
with the gyroscopic matrix frozen at one speed (``gyro_speed``; it is small for
rotors like the RK-4, and the speed varies little across the resonance). Each
complex modal coordinate is then a first-order filter of the unbalance force,
integrated exactly for a force that is linear between samples (first-order hold),
with ``scipy.signal.lfilter``; the start is the steady state at the initial speed.
Per revolution the 1x vector ``Z = (1/pi) * integral of x e^{-i theta} d theta`` is
taken, as a keyphasor-referenced order tracker does, with ``x = A cos(theta + phase)``
giving ``Z = A e^{i phase}``.

The response is *real*-linear in a complex unbalance ``U``: with the angular
acceleration the forcing is ``Re/Im(U (w^2 - i alpha) e^{i theta})`` and, for an
anisotropic rotor, the tracked vector of ``U = i`` is not ``i`` times that of
``U = 1``. Both are returned, so unbalances can still be solved in closed form.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
from scipy.signal import lfilter, lfiltic

__all__ = ["RPM", "runup_order_response", "sweep_parameter", "transient_end_rpm"]

RPM = 2 * np.pi / 60.0  # rad/s per rev/min


def _modal_state(rotor, n_modes, gyro_speed):
    """Lowest undamped modes ``P``, reduced ``M^-1`` and the state matrix at one speed."""
    M, C, G, K = rotor.matrices()
    n_modes = min(n_modes, M.shape[0])
    _, P = sla.eigh(K, M, subset_by_index=[0, n_modes - 1])
    Mr, Cr, Gr, Kr = (P.T @ X @ P for X in (M, C, G, K))
    Minv = np.linalg.inv(Mr)
    A = np.block([[np.zeros((n_modes, n_modes)), np.eye(n_modes)],
                  [-Minv @ Kr, -Minv @ (Cr + gyro_speed * Gr)]])
    return P, Minv, A


def runup_order_response(rotor, rpm_start: float, rpm_end: float, rate_rpm_s: float,
                         probe: float, n_modes: int = 16, samples_per_rev: int = 128,
                         gyro_speed: float | None = None):
    """Per-revolution 1x vectors at a probe during a linear run-up, per unit unbalance.

    Parameters
    ----------
    rotor : BeamRotor
    rpm_start, rpm_end : float
        Speed range of the run-up, rev/min (``rpm_end > rpm_start > 0``).
    rate_rpm_s : float
        Angular acceleration, rpm per second (> 0).
    probe : float
        Axial position of the probe, m.
    n_modes : int
        Undamped modes kept (x and y modes count separately).
    samples_per_rev : int
        Time samples per revolution at ``rpm_end`` (more at lower speeds).
    gyro_speed : float, optional
        Speed (rad/s) at which the gyroscopic matrix is frozen; the middle of the
        run-up by default.

    Returns
    -------
    rpm : ndarray, shape (n_rev,)
        Mean speed of each complete revolution, rev/min.
    Z : ndarray, shape (n_rev, n_disks, 2, 2), complex
        ``Z[k, d, u, c]``: 1x vector (m) of revolution ``k`` on probe channel ``c``
        (0: x, 1: y) for a unit unbalance (kg m) at disk ``d`` with phase ``u``
        (0: ``U = 1``, 1: ``U = i``); a unit unbalance has its heavy spot at the
        keyphasor (``U = 1``) or 90 degrees ahead of it in the direction of rotation.

    Examples
    --------
    >>> from sknarx.rotor.beam import BeamRotor, Disk, Bearing
    >>> rotor = BeamRotor(0.5, 0.01, disks=(Disk(0.25, 0.8, 0.076, 0.025),),
    ...                   bearings=(Bearing(0.0, 1e5, 1e5, 60.0, 60.0),
    ...                             Bearing(0.5, 1e5, 1e5, 60.0, 60.0)))
    >>> rpm, Z = runup_order_response(rotor, 500.0, 3000.0, 300.0, probe=0.25)
    >>> Z.shape[1:]
    (1, 2, 2)
    """
    if not 0 < rpm_start < rpm_end:
        raise ValueError(f"Need 0 < rpm_start < rpm_end, got {rpm_start} and {rpm_end}.")
    if not rate_rpm_s > 0:
        raise ValueError(f"rate_rpm_s must be positive, got {rate_rpm_s}.")
    w0, w1, alpha = rpm_start * RPM, rpm_end * RPM, rate_rpm_s * RPM
    wg = 0.5 * (w0 + w1) if gyro_speed is None else gyro_speed
    P, Minv, A = _modal_state(rotor, n_modes, wg)
    n_modes = P.shape[1]
    lam, V = np.linalg.eig(A)
    Vinv = np.linalg.inv(V)
    j = 4 * rotor.node(probe)
    out_rows = np.hstack([P[[j, j + 2]], np.zeros((2, n_modes))]) @ V  # (2, 2n)

    T = (w1 - w0) / alpha
    h = 2 * np.pi / (w1 * samples_per_rev)
    t = np.arange(int(np.ceil(T / h)) + 1) * h
    w = w0 + alpha * t
    theta = w0 * t + 0.5 * alpha * t * t
    c = (w * w - 1j * alpha) * np.exp(1j * theta)  # U = 1: fx = Re(c), fy = Im(c)
    # first-order hold of each complex mode: y[n] = a y[n-1] + b0 x[n] + b1 x[n-1]
    e = np.exp(lam * h)
    g0 = (e - 1.0) / lam
    g1 = (e - 1.0 - lam * h) / (lam * lam * h)
    b0, b1 = g1, g0 - g1

    # revolution boundaries at exact angles: the tracked vector of revolution k is the
    # difference of the cumulative (trapezoidal) integral of x e^{-i theta} d theta
    n_rev = int(theta[-1] // (2 * np.pi))
    bounds = 2 * np.pi * np.arange(n_rev + 1)
    rpm = np.interp(2 * np.pi * (np.arange(n_rev) + 0.5), theta, w) / RPM
    dth = np.diff(theta)
    kern = np.exp(-1j * theta) / np.pi

    def track(x):
        f = x * kern
        F = np.r_[0.0, np.cumsum(0.5 * (f[1:] + f[:-1]) * dth)]
        Fb = np.interp(bounds, theta, F.real) + 1j * np.interp(bounds, theta, F.imag)
        return np.diff(Fb)

    nd = len(rotor.disks)
    Z = np.empty((n_rev, nd, 2, 2), dtype=complex)
    for d, disk in enumerate(rotor.disks):
        i = 4 * rotor.node(disk.position)
        Bx = Vinv @ np.r_[np.zeros(n_modes), Minv @ P[i]]
        By = Vinv @ np.r_[np.zeros(n_modes), Minv @ P[i + 2]]
        for u, cu in enumerate((c, 1j * c)):
            fx, fy = cu.real, cu.imag
            # steady state at the initial speed: the force is Re(F e^{i w0 t}) per axis
            Fx0, Fy0 = (w0 * w0) * (1.0 if u == 0 else 1j), (w0 * w0) * (-1j if u == 0 else 1.0)
            eta = np.empty((lam.size, t.size), dtype=complex)
            for m in range(lam.size):
                x = Bx[m] * fx + By[m] * fy
                pw = 0.5 * (Bx[m] * Fx0 + By[m] * Fy0)
                qw = 0.5 * (Bx[m] * np.conj(Fx0) + By[m] * np.conj(Fy0))
                ym1 = (pw * np.exp(-1j * w0 * h) / (1j * w0 - lam[m])
                       + qw * np.exp(1j * w0 * h) / (-1j * w0 - lam[m]))
                xm1 = (pw * np.exp(-1j * w0 * h) + qw * np.exp(1j * w0 * h))
                zi = lfiltic([b0[m], b1[m]], [1.0, -e[m]], [ym1], [xm1])
                eta[m], _ = lfilter([b0[m], b1[m]], [1.0, -e[m]], x.astype(complex), zi=zi)
            xy = (out_rows @ eta).real  # (2, n_t): probe x and y
            for ch in range(2):
                Z[:, d, u, ch] = track(xy[ch])
    return rpm, Z


def damped_modes(rotor, n: int = 2, n_modes: int = 8, gyro_speed: float = 0.0):
    """The ``n`` lowest damped modes: natural frequencies (rad/s) and damping ratios.

    Parameters
    ----------
    rotor : BeamRotor
    n : int
        How many modes (a split pair of an anisotropic support is two).
    gyro_speed : float
        Spin speed (rad/s) of the gyroscopic term; 0: at rest.
    """
    _, _, A = _modal_state(rotor, n_modes, gyro_speed)
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))][:n]
    return np.abs(lam), -lam.real / np.abs(lam)


def sweep_parameter(rotor, rate_rpm_s: float, n_modes: int = 8) -> dict:
    """How far a run-up at ``rate_rpm_s`` is from quasi-steady at the first mode.

    Returns the first damped natural frequency (rpm), its damping ratio and
    ``alpha / (zeta^2 w_n^2)``: the sweep crosses the half-power band in about
    ``1 / that`` free-vibration decay times, so values above ~0.1 lower and delay
    the tracked peak and leave a beat behind it (the steady-state response is a
    fair model only well below that).
    """
    wn, zeta = damped_modes(rotor, 1, n_modes)  # at rest: no gyroscopic split
    wn, zeta = float(wn[0]), float(zeta[0])
    alpha = rate_rpm_s * RPM
    return {"first_mode_rpm": float(wn / RPM), "damping_ratio": float(zeta),
            "sweep_parameter": float(alpha / (zeta**2 * wn**2))}


def transient_end_rpm(rotor, rpm_start: float, rpm_end: float, rate_rpm_s: float,
                      tol: float = 0.01, n_modes: int = 8) -> tuple[float, float | None]:
    """Speed above which a run-up's free vibration has decayed below ``tol``.

    Each damped mode crossed between ``rpm_start`` and ``rpm_end`` rings on after the
    crossing and decays as ``exp(-zeta w_n t)``; at a constant rate ``alpha`` it has
    fallen to ``tol`` of its size ``ln(1/tol) / (zeta w_n)`` seconds later, i.e.
    ``alpha ln(1/tol) / (zeta w_n)`` rad/s above the mode. Above the largest such speed
    the steady response is the tracked response to within ``tol``.

    Returns
    -------
    until_rpm : float
        That speed, capped at ``rpm_end``; ``rpm_start`` when no mode is crossed.
    first_mode_rad_s : float or None
        The lowest crossed mode's natural frequency (rad/s), or None.

    Examples
    --------
    >>> from sknarx.rotor.beam import BeamRotor, Disk, Bearing
    >>> rotor = BeamRotor(0.5, 0.01, disks=(Disk(0.25, 0.8, 0.076, 0.025),),
    ...                   bearings=(Bearing(0.0, 1e5, 1e5, 60.0, 60.0),
    ...                             Bearing(0.5, 1e5, 1e5, 60.0, 60.0)))
    >>> until, w1 = transient_end_rpm(rotor, 500.0, 6000.0, 300.0)
    >>> bool(w1 / RPM < until < 6000.0)
    True
    """
    wn, zeta = damped_modes(rotor, n_modes // 2, n_modes)
    crossed = (wn >= rpm_start * RPM) & (wn <= rpm_end * RPM)
    if not crossed.any():
        return float(rpm_start), None
    alpha = rate_rpm_s * RPM
    ends = wn[crossed] + alpha * np.log(1.0 / tol) / np.maximum(zeta[crossed] * wn[crossed],
                                                                1e-12)
    return float(min(ends.max() / RPM, rpm_end)), float(wn[crossed].min())
