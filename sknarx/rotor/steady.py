"""The settled response at a constant speed by harmonic balance, instead of integration.

A rotor whose response is locked to the shaft revolution settles on an orbit of period
``2 pi / omega``: its displacements are a Fourier series in the shaft angle, and the
equations of motion hold harmonic by harmonic (harmonic balance). The linear rotor
acts on each harmonic through its dynamic stiffness ``K - (k omega)^2 M + i k omega
(C + omega G)``; gravity, the unbalance, the ball bearings and the effects' forces are
evaluated on instants of one revolution and transformed back (alternating
frequency-time, Cameron & Griffin 1989). Newton's method solves the balance, with the
bearings' tangent stiffness in closed form and the effects' by differences; a start
close to the answer (the previous solution at the same speed) converges in two or
three iterations, which is what a calibration's thousands of nearby parameter points
need. See Krack & Gross (2019), *Harmonic Balance for Nonlinear Vibration Problems*,
for the method.

What the balance leaves out, and when to integrate instead:

* the ball passage exactly: the balance averages the bearings over the cage angle and
  adds the varying-compliance line (``ball_pass_ratio`` times the shaft speed, not an
  integer order) and its sidebands to first order (:func:`ball_pass_lines`); the
  tests compare the result order by order with the integrator;
* an orbit that is not the shaft-periodic one: a contact that makes 1/2x, 1/3x or
  chaos, a speed that fluctuates. Such effects say so (``Effect.shaft_periodic``
  False); :func:`supports_harmonic_balance` sends those that change the speed or the
  rotor's parameters to the integrator, and :func:`solve_steady_state` declines
  (:class:`HarmonicBalanceError`) an orbit on which a contact's force acts -- a rub
  whose clearance the orbit never reaches is balanced, one it touches is integrated;
* a record that starts from rest: its transient is what it shows.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from . import _hb_kernels as hbk
from .effects import Effect, builtin_forces, compose_force_kernels

__all__ = ["SteadyState", "HarmonicBalanceError", "solve_steady_state", "ball_pass_lines",
           "supports_harmonic_balance", "steady_columns"]

#: cage positions the bearings are averaged over, across one ball pitch: the mean of a
#: periodic function by the trapezoidal rule, 8 points put the averaged force within
#: 1e-4 of its limit at the static load (checked in the tests against 64 points)
N_CAGE = 8


#: the record grids' bases (shaft orders, ball-pass lines) by speed and grid: a 19-speed
#: sweep needs 19
_BASES: dict = {}
_BASES_LOCK = threading.Lock()
_MAX_BASES = 64
_NO_JACOBIAN = (np.empty(0, dtype=np.int64), np.empty((0, 0)), np.empty((0, 0)))


class HarmonicBalanceError(RuntimeError):
    """The harmonic balance did not converge (integrate instead)."""


@dataclass(frozen=True)
class SteadyState:
    """The settled, shaft-periodic response of a rotor at one speed.

    ``x_i(t) = c_i0 + sum_k c_ik cos(k omega t) + s_ik sin(k omega t)`` with the
    shaft angle 0 at ``t = 0`` (as in a simulated record).

    Attributes
    ----------
    omega : float
        Shaft speed, rad/s.
    coefficients : ndarray (n_dof, 2 harmonics + 1)
        Constant, then the cosine and sine of each order (m, rad).
    dof_names : tuple of str
    iterations : int
        Newton iterations taken.
    residual : float
        Largest harmonic force imbalance over the largest applied force (gravity,
        unbalance).
    lines : tuple of ndarray or None
        The ball passage's first-order response: frequencies ``Omega`` (rad/s, shape
        ``(L,)``) and complex amplitudes ``X`` (``(L, n_dof)``, m), adding ``2 Re(X
        e^{i Omega t})`` (see :func:`ball_pass_lines`); None: left out.
    """

    omega: float
    coefficients: np.ndarray
    dof_names: tuple
    iterations: int
    residual: float
    lines: tuple | None = None
    # the balance's condensed Jacobian at this solution (active DOFs, their force
    # tangents' harmonics, the inverse of the condensed matrix): a nearby balance's
    # chord steps use it
    _jacobian: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def harmonics(self) -> int:
        """Highest shaft order held."""
        return (self.coefficients.shape[1] - 1) // 2

    def displacements(self, t) -> np.ndarray:
        """Displacements (m, rad) at times ``t`` (s), shape ``(len(t), n_dof)``: the
        shaft orders and, where kept, the ball passage's lines."""
        return self._sampled(np.asarray(t, dtype=float))

    def _sampled(self, t, key=None):
        """:meth:`displacements`; ``key`` (hashable, naming ``t``) keeps the basis of
        those instants for the next state at the same speed (a calibration samples
        thousands on the same record grid)."""
        basis = _BASES.get(key) if key is not None else None
        if basis is None:
            lines = (np.exp(1j * np.outer(t, self.lines[0])) if self.lines is not None
                     else None)
            basis = (_synthesis(self.omega * t, self.harmonics), lines)
            if key is not None:
                with _BASES_LOCK:  # the simulation threads sample concurrently
                    if len(_BASES) >= _MAX_BASES:  # the oldest makes room (dicts keep order)
                        _BASES.pop(next(iter(_BASES)), None)
                    _BASES[key] = basis
        out = basis[0] @ self.coefficients.T
        if self.lines is not None:
            out += 2.0 * (basis[1] @ self.lines[1]).real
        return out

    def state_at(self, t: float):
        """``(q, v)``: displacements (m, rad) and velocities (m/s, rad/s) at time ``t``
        (s), an integration's initial state on this orbit."""
        t = float(t)
        q = self.displacements(np.array([t]))[0]
        H = self.harmonics
        k = np.arange(1, H + 1) * self.omega
        c = self.coefficients
        ph = k * t
        v = (c[:, 2::2] * (k * np.cos(ph)) - c[:, 1::2] * (k * np.sin(ph))).sum(axis=1)
        if self.lines is not None:
            Omega, X = self.lines
            v = v + 2.0 * ((1j * Omega * np.exp(1j * Omega * t)) @ X).real
        return q, v

    def order_vector(self, order: int) -> np.ndarray:
        """Each DOF's complex vector ``A e^{i phase}`` of shaft order ``order``
        (``x ~ A cos(order phi + phase)``), m."""
        k = int(order)
        if not 1 <= k <= self.harmonics:
            raise ValueError(f"order must be an integer in 1..{self.harmonics}, got {order!r}.")
        c = self.coefficients
        return c[:, 2 * k - 1] - 1j * c[:, 2 * k]


def _synthesis(phase, H):
    B = np.empty((phase.size, 2 * H + 1))
    B[:, 0] = 1.0
    for k in range(1, H + 1):
        B[:, 2 * k - 1] = np.cos(k * phase)
        B[:, 2 * k] = np.sin(k * phase)
    return B


def ball_pass_lines(sim, coefficients, omega, n_orders=2):
    """The ball passage's response to first order about a balanced orbit.

    The balance averages each bearing over its cage angle; what the average leaves out
    is the force's variation with the balls' positions, ``F(q, theta) - mean_theta F``,
    periodic in the cage angle ``theta`` over one ball pitch. Along the orbit the cage
    turns at ``cage_ratio`` times the shaft, so that variation drives the rotor at
    ``(k + l BPR) omega`` (``BPR = n_balls cage_ratio``, the ball-pass ratio; ``l =
    1..n_orders``, ``k`` the shaft orders): the varying-compliance line and its
    sidebands. Each line's response is the linear rotor's (bearings at their static
    stiffness) to that force -- first order in the variation, which on a gravity-loaded
    bearing is a few per cent of its static force.

    Parameters
    ----------
    sim : RotorBearingSimulator
    coefficients : ndarray (n_dof, 2 H + 1)
        The balanced orbit (:attr:`SteadyState.coefficients`).
    omega : float
        Speed, rad/s.
    n_orders : int, default=2
        Harmonics ``l`` of the ball passage kept.

    Returns
    -------
    Omega : ndarray (L,)
        Line frequencies, rad/s (negative: the conjugate sense).
    X : ndarray (L, n_dof)
        Complex amplitudes (m, rad); the response is ``2 Re(X e^{i Omega t})``.
    """
    s = sim._setup
    p = sim.effective_params
    n, width = coefficients.shape
    H = (width - 1) // 2
    N = 4 * H + 4
    phi = 2.0 * np.pi * np.arange(N) / N
    Q = _synthesis(phi, H) @ coefficients.T
    Fc = hbk.cage_forces(np.ascontiguousarray(Q), s.brg, N_CAGE)  # (N, S, bearing, axis)
    Fl = np.fft.fft(Fc, axis=1)[:, 1:n_orders + 1] / N_CAGE       # cage harmonics l >= 1
    C = np.fft.fft(Fl, axis=0) / N                                # shaft orders k
    k = np.rint(np.fft.fftfreq(N, 1.0 / N)).astype(int)
    keep = np.abs(k) <= H
    C, k = C[keep], k[keep]
    ls = np.arange(1, n_orders + 1)
    Omega = ((k[:, None] + ls[None, :] * p.ball_pass_ratio) * omega).ravel()
    P = np.zeros((Omega.size, n), dtype=complex)
    brg = s.brg
    for b in range(2):
        ix, iy = int(brg[5 + 2 * b]), int(brg[6 + 2 * b])
        hx, hy = int(brg[11 + 2 * b]), int(brg[12 + 2 * b])
        fx, fy = C[:, :, b, 0].ravel(), C[:, :, b, 1].ravel()
        P[:, ix] += fx
        P[:, iy] += fy
        if hx >= 0:
            P[:, hx] -= fx
            P[:, hy] -= fy
    D = (sim.linear_stiffness[None] - (Omega ** 2)[:, None, None] * sim.matrices.M[None]
         + 1j * Omega[:, None, None] * (s.C + omega * s.G)[None])
    return Omega, np.linalg.solve(D, P[:, :, None])[:, :, 0]


def _force_only(effect) -> bool:
    """Whether ``effect`` acts through its force kernel alone (no parameter, speed or
    support change)."""
    kind = type(effect)
    return (kind.modify_parameters is Effect.modify_parameters
            and kind.modify_speed is Effect.modify_speed and effect.pedestals() is None)


def supports_harmonic_balance(sim) -> bool:
    """Whether harmonic balance may give the settled response of simulator ``sim``.

    Every effect must be locked to the shaft revolution (``shaft_periodic``), or act
    through a force alone -- a rub, a loose joint -- which :func:`solve_steady_state`
    then checks is nil along the balanced orbit (where such a force acts, the orbit may
    be sub-synchronous or chaotic: integrate); and the force kernels must be the
    package's own (a user's kernel is integrated)."""
    for e in sim.effects:
        if type(e).modify_speed is not Effect.modify_speed:
            return False
        if not (getattr(e, "shaft_periodic", False) or _force_only(e)):
            return False
    return sim._setup.kernel is builtin_forces


def _idle_program(sim):
    """The force program of the effects of ``sim`` that may leave the shaft-periodic
    orbit where they act (empty when there are none)."""
    ctx = sim._setup.context
    kernels = [k for e in sim.effects if not getattr(e, "shaft_periodic", False)
               if (k := e.force_kernel(ctx)) is not None]
    if not kernels:
        return None
    kernel, program = compose_force_kernels(kernels)
    if kernel is not builtin_forces:
        raise HarmonicBalanceError("a user's force kernel cannot be checked")
    return program


#: the excursion margin within which a contact-like effect must stay idle: its force
#: is evaluated on the balanced orbit enlarged by this factor about the static
#: deflection (at the disks and the joint, where the contacts act, the ball-pass lines
#: are below 0.1 % of the orbit; the margin covers them fifty times over)
IDLE_MARGIN = 1.05


def solve_steady_state(sim, omega, harmonics=8, start=None, tol=1e-8, max_iter=25,
                       keep_jacobian=False, ball_pass=True):
    """The shaft-periodic steady state of simulator ``sim`` at ``omega`` rad/s.

    Parameters
    ----------
    sim : RotorBearingSimulator
    omega : float
        Speed, rad/s (> 0).
    harmonics : int, default=8
        Highest shaft order kept (the gap map reads up to 3x and fits 4x and 5x; the
        orders above carry the contact forces' harmonics so that they do not alias).
    start : SteadyState, optional
        A nearby solution (the same DOFs and harmonics) to start from; by default the
        static deflection.
    tol : float, default=1e-8
        Convergence: largest harmonic imbalance relative to the largest applied force
        (on a breathing crack's orbit it leaves the orders within 1e-9 of their
        converged values).
    max_iter : int, default=25
        Newton iterations before giving up.
    keep_jacobian : bool, default=False
        Keep the balance's Jacobian at the solution in the result, so that a balance
        started from it (``start``) takes chord steps instead of Newton's.
    ball_pass : bool, default=True
        Add the ball passage's lines to first order (:func:`ball_pass_lines`).

    Returns
    -------
    SteadyState

    Raises
    ------
    HarmonicBalanceError
        If Newton's method does not converge (the caller integrates instead).

    Examples
    --------
    >>> from sknarx.rotor import RotorBearingSimulator
    >>> from sknarx.rotor import solve_steady_state
    >>> sim = RotorBearingSimulator()
    >>> state = solve_steady_state(sim, 150.0)
    >>> x_O1 = state.dof_names.index("xO1")
    >>> round(abs(state.order_vector(1)[x_O1]) * 1e6)  # disk O1's 1x amplitude, um
    1052
    """
    omega = float(omega)
    if not (np.isfinite(omega) and omega > 0):
        raise ValueError(f"omega must be a positive speed in rad/s, got {omega!r}.")
    s = sim._setup
    M = sim.matrices.M
    n = M.shape[0]
    H = int(harmonics)
    m = 2 * H + 1
    N = 4 * H + 4  # instants per revolution: the product of two orders up to H unaliased
    t, E, D, W = hbk.basis(omega, H, N)
    warm = start is not None and start.coefficients.shape == (n, m)
    if warm:
        z0 = start.coefficients.ravel()
        act0, G0, Minv0 = start._jacobian or _NO_JACOBIAN
    else:
        z0 = np.zeros(n * m)
        z0[::m] = s.context.q_static
        act0, G0, Minv0 = _NO_JACOBIAN
    scale = max(float(np.max(np.abs(s.fg))), float(np.max(np.abs(s.unb[:, 0]))) * omega ** 2,
                1e-12)
    # the linear operator holds the bearings' static stiffness (the shaft alone is free
    # at the constant harmonic); the forces take it back
    K = sim.linear_stiffness
    z, act, G, Minv, it, res, status = hbk.solve(
        z0, act0, G0, Minv0, t, E, D, W, omega, M, s.C + omega * s.G, K, s.fg, s.unb,
        s.brg, s.kparams, N_CAGE, K - s.K, scale, float(tol), int(max_iter),
        bool(keep_jacobian))
    if status != 0:
        raise HarmonicBalanceError(
            f"harmonic balance {'stalled' if status == 1 else 'did not converge'} at "
            f"{omega:g} rad/s after {it} iterations (imbalance {res:.2g})")
    limit = sim.divergence_limit
    if math.isfinite(limit) and np.max(np.abs(z.reshape(n, m)).sum(axis=1)) > limit:
        raise HarmonicBalanceError(f"the balanced orbit at {omega:g} rad/s exceeds the "
                                   f"divergence limit {limit} m")
    program = _idle_program(sim)
    if program is not None:
        tc, Ec, Dc, _ = hbk.basis(omega, H, 4 * N)
        if hbk.largest_extra_force(z, tc, Ec, Dc, omega, program, s.context.q_static,
                                   IDLE_MARGIN) != 0.0:
            acting = ", ".join(e.name for e in sim.effects if not e.shaft_periodic)
            raise HarmonicBalanceError(
                f"at {omega:g} rad/s the {acting} acts on the balanced orbit, which may "
                "then not be the settled one")
    coefficients = z.reshape(n, m).copy()
    return SteadyState(omega=omega, coefficients=coefficients,
                       dof_names=tuple(sim.dof_names), iterations=it, residual=res,
                       lines=ball_pass_lines(sim, coefficients, omega) if ball_pass else None,
                       _jacobian=(act, G, Minv) if Minv.shape[0] else None)


def steady_columns(sim, state: SteadyState, fs, n_samples):
    """A settled record of ``state`` as :meth:`RotorBearingSimulator.simulate_columns`
    returns it: ``speed``, ``t``, ``u``, ``phi`` and the DOFs sampled at ``fs`` Hz from
    ``t = 0`` (shaft angle 0), through the simulator's measurement effects."""
    n = int(n_samples)
    t = np.arange(n) / float(fs)
    phi = state.omega * t
    s = sim._setup
    me1, ph1 = s.unb[0, 0], s.unb[0, 1]
    columns = {"speed": np.full(n, state.omega), "t": t,
               "u": me1 * state.omega ** 2 * np.cos(phi + ph1), "phi": phi}
    key = (state.omega, state.harmonics, float(fs), n,
           None if state.lines is None else state.lines[0].tobytes())
    columns.update(zip(state.dof_names, state._sampled(t, key).T, strict=True))
    return sim._measure(columns, state.omega, n)
