"""Fixed-step fourth-order Runge-Kutta integrator, compiled with numba.

The right-hand side is the rotor's linear part ``M^-1 (F - (C + Omega G) v - K q)``
plus three nonlinear/forcing contributions: unbalance (with the angular
acceleration term of a speed profile), gravity and the two ball bearings (against
the frame, or between journal and housing when the rotor has pedestals). Any
further physics enters through ONE hook, ``extra_force(t, phi, omega, alpha, q, v,
params, out)``, a numba-compiled function that adds generalised forces to
``out``; effects (rub, crack, misalignment, looseness...) are composed into such a
function outside this module (see :mod:`sknarx.rotor.effects`), so the
integrator never changes when physics is added. The package's own effects always
arrive as one program of :func:`~sknarx.rotor.effects.builtin_forces`; that path is
cached on disk by numba, a user's own kernels are compiled per process.

Within one output sample the speed varies linearly (exact for piecewise-linear
speed profiles), and the shaft angle is integrated analytically.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .bearings import ball_pitch, bearing_force_at, cage_angle
from .effects import builtin_forces

__all__ = ["integrate"]


@njit(nogil=True, inline="always")
def _angles(phi, unb, brg, out):  # pragma: no cover
    """The trigonometry of shaft angle ``phi`` that the forces need: each disk's
    unbalance angle's (cos, sin) at 0-3 and the cage angle's at 4-5. RK-4's second and
    third stages evaluate the same instant, so one call serves both."""
    for d in range(2):
        a = phi + unb[d, 1]
        out[2 * d] = math.cos(a)
        out[2 * d + 1] = math.sin(a)
    out[4], out[5] = cage_angle(phi, brg[4])


@njit(nogil=True, inline="always")
def _accel(t, phi, w, al, q, v, minv, Ct, Gt, Kt, fg, unb, brg, pitch, trig, extra, eparams,
           f, acc):  # pragma: no cover
    n = q.shape[0]
    for i in range(n):
        f[i] = fg[i]
    # unbalance of the two disks: m e (w^2 cos + alpha sin, w^2 sin - alpha cos)
    for d in range(2):
        me, ix, iy = unb[d, 0], int(unb[d, 2]), int(unb[d, 3])
        c, s = trig[2 * d], trig[2 * d + 1]
        f[ix] += me * (w * w * c + al * s)
        f[iy] += me * (w * w * s - al * c)
    expo, nb = brg[2], int(brg[3])
    for b in range(2):
        ix, iy = int(brg[5 + 2 * b]), int(brg[6 + 2 * b])
        # bearing A's contact stiffness and clearance at 0, 1; bearing B's at 9, 10;
        # the housings' DOFs at 11-14 (-1: held by the frame)
        kB, gamma = (brg[0], brg[1]) if b == 0 else (brg[9], brg[10])
        hx, hy = int(brg[11 + 2 * b]), int(brg[12 + 2 * b])
        x, y = q[ix], q[iy]
        if hx >= 0:  # the contact between journal and housing
            x -= q[hx]
            y -= q[hy]
        fx, fy = bearing_force_at(x, y, trig[4], trig[5], pitch[0], pitch[1], kB, gamma,
                                  expo, nb)
        f[ix] += fx
        f[iy] += fy
        if hx >= 0:  # and its reaction on the housing
            f[hx] -= fx
            f[hy] -= fy
    extra(t, phi, w, al, q, v, eparams, f)
    # column by column (the matrices come transposed, see integrate): each row's terms
    # are summed in the same order as a row-by-row product, bit for bit, but the rows'
    # updates are independent and vectorise; about a fifth off every integration step
    for i in range(n):
        acc[i] = f[i]
    for j in range(n):
        vj, qj = v[j], q[j]
        for i in range(n):
            acc[i] -= (Ct[j, i] + w * Gt[j, i]) * vj + Kt[j, i] * qj
    for i in range(n):
        acc[i] *= minv[i]


def integrate(q0, v0, omega, phi0, t0, dt, substeps, record_from, minv, C, G, K, fg, unb,
              brg, extra, eparams, limit):
    """Integrate over ``len(omega) - 1`` sample intervals.

    Parameters
    ----------
    omega : (n + 1,) speed at each sample instant, rad/s (linear in between).
    record_from : first sample index that is recorded.
    extra, eparams : the force hook and its parameters (see the module's docstring).
    limit : a generalised coordinate beyond this magnitude counts as divergence.

    Returns
    -------
    Q : (n + 1 - record_from, ndof) recorded displacements.
    U : (n + 1 - record_from,) the paper's input, disk O1's x unbalance force, N.
    PHI : (n + 1 - record_from,) shaft angle, rad.
    status : -1, or the sample index at which the solution diverged.
    q, v : (ndof,) the state at the last sample (to continue a run from).
    """
    args = (q0, v0, omega, phi0, t0, dt, substeps, record_from, minv, C, G, K, fg, unb, brg)
    if extra is builtin_forces:
        return _integrate_builtin(*args, eparams, limit)
    return _rk4(*args, extra, eparams, limit)


# numba cannot cache a function whose argument is a function (the hook's type names
# the compiled object, not its code), so the loop alone was compiled afresh in every
# process (tens of seconds: each test worker, CLI start and benchmark process paid
# it). The package's own effects always arrive as one program of ``builtin_forces``;
# this entry point calls that as a global, which numba can cache, and only a user's
# own kernels run the loop with the hook (``_rk4`` called directly).
@njit(nogil=True, cache=True)
def _integrate_builtin(q0, v0, omega, phi0, t0, dt, substeps, record_from, minv, C, G, K,
                       fg, unb, brg, eparams, limit):  # pragma: no cover
    return _rk4(q0, v0, omega, phi0, t0, dt, substeps, record_from, minv, C, G, K, fg, unb,
                brg, builtin_forces, eparams, limit)


# inlined where jitted code calls it, so that the hook is a compile-time constant in
# the cached entry point (passing it as a value would embed its address and forbid the
# cache); called from Python (a user's kernels) it is compiled on its own as usual
@njit(nogil=True, inline="always")
def _rk4(q0, v0, omega, phi0, t0, dt, substeps, record_from, minv, C, G, K, fg, unb, brg,
         extra, eparams, limit):  # pragma: no cover
    n = omega.shape[0] - 1
    ndof = q0.shape[0]
    nrec = n + 1 - record_from
    Q = np.empty((nrec, ndof))
    U = np.empty(nrec)
    PHI = np.empty(nrec)
    q = q0.copy()
    v = v0.copy()
    f = np.empty(ndof)
    k1q = np.empty(ndof)
    k1v = np.empty(ndof)
    k2q = np.empty(ndof)
    k2v = np.empty(ndof)
    k3q = np.empty(ndof)
    k3v = np.empty(ndof)
    k4q = np.empty(ndof)
    k4v = np.empty(ndof)
    qt = np.empty(ndof)
    vt = np.empty(ndof)
    # transposed, contiguous: _accel walks them column by column
    Ct = np.ascontiguousarray(C.T)
    Gt = np.ascontiguousarray(G.T)
    Kt = np.ascontiguousarray(K.T)
    pitch = np.empty(2)
    pitch[0], pitch[1] = ball_pitch(int(brg[3]))
    trig = np.empty(6)
    h = dt / substeps
    phi = phi0
    me1, ph1 = unb[0, 0], unb[0, 1]
    for k in range(n + 1):
        wk = omega[k]
        al = (omega[k + 1] - wk) / dt if k < n else 0.0
        if k >= record_from:
            r = k - record_from
            for i in range(ndof):
                Q[r, i] = q[i]
            c, s = math.cos(phi + ph1), math.sin(phi + ph1)
            U[r] = me1 * (wk * wk * c + al * s)
            PHI[r] = phi
        bad = False
        for i in range(ndof):
            if not (abs(q[i]) <= limit):
                bad = True
        if bad:
            return Q, U, PHI, k, q, v
        if k == n:
            break
        tk = t0 + k * dt
        for sub in range(substeps):
            tau = sub * h
            ta = tk + tau
            wa = wk + al * tau
            pa = phi + wk * tau + 0.5 * al * tau * tau
            wm = wa + 0.5 * al * h
            pm = pa + wa * 0.5 * h + 0.125 * al * h * h
            we = wa + al * h
            pe = pa + wa * h + 0.5 * al * h * h
            for i in range(ndof):
                k1q[i] = v[i]
            _angles(pa, unb, brg, trig)
            _accel(ta, pa, wa, al, q, v, minv, Ct, Gt, Kt, fg, unb, brg, pitch, trig, extra,
                   eparams, f, k1v)
            for i in range(ndof):
                qt[i] = q[i] + 0.5 * h * k1q[i]
                vt[i] = v[i] + 0.5 * h * k1v[i]
                k2q[i] = vt[i]
            _angles(pm, unb, brg, trig)
            _accel(ta + 0.5 * h, pm, wm, al, qt, vt, minv, Ct, Gt, Kt, fg, unb, brg, pitch,
                   trig, extra, eparams, f, k2v)
            for i in range(ndof):
                qt[i] = q[i] + 0.5 * h * k2q[i]
                vt[i] = v[i] + 0.5 * h * k2v[i]
                k3q[i] = vt[i]
            _accel(ta + 0.5 * h, pm, wm, al, qt, vt, minv, Ct, Gt, Kt, fg, unb, brg, pitch,
                   trig, extra, eparams, f, k3v)  # the same instant: the same angles
            for i in range(ndof):
                qt[i] = q[i] + h * k3q[i]
                vt[i] = v[i] + h * k3v[i]
                k4q[i] = vt[i]
            _angles(pe, unb, brg, trig)
            _accel(ta + h, pe, we, al, qt, vt, minv, Ct, Gt, Kt, fg, unb, brg, pitch, trig,
                   extra, eparams, f, k4v)
            for i in range(ndof):
                q[i] += h / 6.0 * (k1q[i] + 2.0 * k2q[i] + 2.0 * k3q[i] + k4q[i])
                v[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i])
        phi += 0.5 * (wk + omega[k + 1]) * dt
    return Q, U, PHI, -1, q, v
