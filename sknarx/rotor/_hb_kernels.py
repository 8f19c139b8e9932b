"""Compiled kernels of the harmonic balance (see :mod:`sknarx.rotor.steady`).

The periodic response is held as real Fourier coefficients, DOF by DOF: ``z[i * m +
p]`` with ``p = 0`` the constant and ``2k - 1``, ``2k`` the cosine and sine of
``k nu t`` (``nu`` the base frequency, ``m = 2H + 1``). The forces are evaluated on
``N`` instants of one period (alternating frequency-time): gravity, unbalance, the two
ball bearings averaged over the cage angle, and the effects' force program
(:func:`~sknarx.rotor.effects.builtin_forces`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .bearings import ball_pitch, bearing_force_at
from .effects import builtin_forces

#: a chord step (a nearby solution's Jacobian) is kept while it cuts the imbalance at
#: least this much; slower, Newton's steps (quadratic) take over
CHORD_RATE = 0.1


@njit(nogil=True, cache=True)
def basis(nu, H, N):  # pragma: no cover
    """Instants ``t`` (s) of one period ``2 pi / nu``, the basis ``E`` (N, 2H+1), its
    time derivative ``D`` and the Galerkin weights ``W`` (coefficients of a sampled
    periodic signal ``x``: ``W * (E.T @ x)``)."""
    m = 2 * H + 1
    T = 2.0 * math.pi / nu
    t = np.empty(N)
    E = np.empty((N, m))
    D = np.empty((N, m))
    for j in range(N):
        tj = T * j / N
        t[j] = tj
        E[j, 0] = 1.0
        D[j, 0] = 0.0
        for k in range(1, H + 1):
            c, s = math.cos(k * nu * tj), math.sin(k * nu * tj)
            E[j, 2 * k - 1] = c
            E[j, 2 * k] = s
            D[j, 2 * k - 1] = -k * nu * s
            D[j, 2 * k] = k * nu * c
    W = np.full(m, 2.0 / N)
    W[0] = 1.0 / N
    return t, E, D, W


@njit(nogil=True, cache=True, inline="always")
def _bearing_mean(x, y, kB, gamma, expo, nb, n_cage, cs, ss, out):  # pragma: no cover
    """A ball bearing's force on the journal at ``(x, y)`` (m) averaged over the cage's
    angle across one ball pitch (``n_cage`` positions), and its tangent stiffness:
    ``out`` = (fx, fy, dfx/dx, dfx/dy, dfy/dx, dfy/dy)."""
    for i in range(6):
        out[i] = 0.0
    w = 1.0 / n_cage
    for s in range(n_cage):
        th = 2.0 * math.pi / nb * (s + 0.5) / n_cage
        c, sn = math.cos(th), math.sin(th)
        for _ in range(nb):
            d = x * c + y * sn - gamma
            if d > 0.0:
                root = math.sqrt(d)
                if expo == 1.5:
                    f = kB * d * root
                    df = 1.5 * kB * root
                else:
                    f = kB * d**expo
                    df = expo * kB * d ** (expo - 1.0)
                out[0] -= w * f * c
                out[1] -= w * f * sn
                out[2] -= w * df * c * c
                out[3] -= w * df * c * sn
                out[4] -= w * df * sn * c
                out[5] -= w * df * sn * sn
            c, sn = c * cs - sn * ss, sn * cs + c * ss


@njit(nogil=True, cache=True, inline="always")
def _journal(Q, j, brg, b):  # pragma: no cover
    """Bearing ``b``'s journal DOFs, housing DOFs (-1: the frame), contact stiffness,
    clearance and the journal's displacement in its bearing at instant ``j``."""
    ix, iy = int(brg[5 + 2 * b]), int(brg[6 + 2 * b])
    kB, gamma = (brg[0], brg[1]) if b == 0 else (brg[9], brg[10])
    hx, hy = int(brg[11 + 2 * b]), int(brg[12 + 2 * b])
    x, y = Q[j, ix], Q[j, iy]
    if hx >= 0:
        x -= Q[j, hx]
        y -= Q[j, hy]
    return ix, iy, hx, hy, kB, gamma, x, y


@njit(nogil=True, cache=True)
def forces(z, t, E, D, omega, fg, unb, brg, eparams, n_cage, Kb, want_tangents, Q, V, F,
           A, B):  # pragma: no cover
    """The response ``Q``, ``V`` (N, n) on the instants ``t`` and the forces ``F`` on
    them, plus ``Kb q`` (``Kb``: the bearings' stiffness the linear operator holds, so
    that it is not singular at the constant); with ``want_tangents``, their tangents
    ``A = dF/dq`` and ``B = dF/dv`` (N, n, n): the bearings' in closed form, the
    effects' by forward differences."""
    N, m = E.shape
    n = fg.shape[0]
    for j in range(N):
        for i in range(n):
            a = 0.0
            b = 0.0
            for p in range(m):
                a += E[j, p] * z[i * m + p]
                b += D[j, p] * z[i * m + p]
            Q[j, i] = a
            V[j, i] = b
    cs, ss = ball_pitch(int(brg[3]))
    expo, nb = brg[2], int(brg[3])
    has_extra = eparams.shape[0] > 0 and eparams[0] > 0
    kb = np.empty(6)
    f0 = np.empty(n)
    f1 = np.empty(n)
    qp = np.empty(n)
    vp = np.empty(n)
    for j in range(N):
        phi = omega * t[j]
        for i in range(n):
            acc = fg[i]
            for k in range(n):
                acc += Kb[i, k] * Q[j, k]
            F[j, i] = acc
        for d in range(2):
            me, ix, iy = unb[d, 0], int(unb[d, 2]), int(unb[d, 3])
            a = phi + unb[d, 1]
            F[j, ix] += me * omega * omega * math.cos(a)
            F[j, iy] += me * omega * omega * math.sin(a)
        if want_tangents:
            for i in range(n):
                for k in range(n):
                    A[j, i, k] = Kb[i, k]
                    B[j, i, k] = 0.0
        for b in range(2):
            ix, iy, hx, hy, kB, gamma, x, y = _journal(Q, j, brg, b)
            _bearing_mean(x, y, kB, gamma, expo, nb, n_cage, cs, ss, kb)
            F[j, ix] += kb[0]
            F[j, iy] += kb[1]
            if hx >= 0:
                F[j, hx] -= kb[0]
                F[j, hy] -= kb[1]
            if want_tangents:
                rows = (ix, iy)
                for r in range(2):
                    for c in range(2):
                        A[j, rows[r], rows[c]] += kb[2 + 2 * r + c]
                if hx >= 0:
                    hrows = (hx, hy)
                    for r in range(2):
                        for c in range(2):
                            g = kb[2 + 2 * r + c]
                            A[j, rows[r], hrows[c]] -= g
                            A[j, hrows[r], rows[c]] -= g
                            A[j, hrows[r], hrows[c]] += g
        if has_extra:
            for i in range(n):
                f0[i] = 0.0
                qp[i] = Q[j, i]
                vp[i] = V[j, i]
            builtin_forces(t[j], phi, omega, 0.0, qp, vp, eparams, f0)
            for i in range(n):
                F[j, i] += f0[i]
            if want_tangents:
                # forward differences in each displacement (into A), then each velocity
                # (into B); the floors are a displacement's and a velocity's roundoff
                for which in range(2):
                    x = qp if which == 0 else vp
                    T = A if which == 0 else B
                    floor = 1e-10 if which == 0 else 1e-8
                    for k in range(n):
                        held = x[k]
                        h = floor + 1e-7 * abs(held)
                        x[k] = held + h
                        for i in range(n):
                            f1[i] = 0.0
                        builtin_forces(t[j], phi, omega, 0.0, qp, vp, eparams, f1)
                        x[k] = held
                        for i in range(n):
                            T[j, i, k] += (f1[i] - f0[i]) / h


@njit(nogil=True, cache=True)
def residual(z, nu, H, M, CG, K, F, E, W, R):  # pragma: no cover
    """``R = L z - W E^T F``: the linear rotor's dynamic stiffness on each harmonic
    minus the harmonics of the forces (N, per DOF)."""
    n = M.shape[0]
    m = 2 * H + 1
    N = E.shape[0]
    for i in range(n):
        for p in range(m):
            acc = 0.0
            for j in range(N):
                acc += E[j, p] * F[j, i]
            R[i * m + p] = -W[p] * acc
        acc = 0.0
        for l in range(n):
            acc += K[i, l] * z[l * m]
        R[i * m] += acc
        for k in range(1, H + 1):
            w = k * nu
            ac = 0.0
            as_ = 0.0
            for l in range(n):
                kk = K[i, l] - w * w * M[i, l]
                cc = w * CG[i, l]
                ac += kk * z[l * m + 2 * k - 1] + cc * z[l * m + 2 * k]
                as_ += kk * z[l * m + 2 * k] - cc * z[l * m + 2 * k - 1]
            R[i * m + 2 * k - 1] += ac
            R[i * m + 2 * k] += as_


@njit(nogil=True, cache=True)
def linear_inverses(omega, H, M, CG, K):  # pragma: no cover
    """The inverse dynamic stiffness of the linear rotor on each harmonic: ``K^-1`` on
    the constants and, for order ``k``, the inverse of ``[[Kd, w CG], [-w CG, Kd]]``
    (``Kd = K - w^2 M``, ``w = k omega``) acting on the cosines then the sines."""
    n = M.shape[0]
    L0 = np.linalg.inv(K)
    Lk = np.empty((H, 2 * n, 2 * n))
    blk = np.empty((2 * n, 2 * n))
    for k in range(1, H + 1):
        w = k * omega
        for i in range(n):
            for l in range(n):
                kd = K[i, l] - w * w * M[i, l]
                cc = w * CG[i, l]
                blk[i, l] = kd
                blk[i, n + l] = cc
                blk[n + i, l] = -cc
                blk[n + i, n + l] = kd
        Lk[k - 1] = np.linalg.inv(blk)
    return L0, Lk


@njit(nogil=True, cache=True)
def _apply_linear_inverse(L0, Lk, R, out):  # pragma: no cover
    """``out = L^-1 R`` harmonic by harmonic (layout ``i * m + p``)."""
    n = L0.shape[0]
    H = Lk.shape[0]
    m = 2 * H + 1
    for i in range(n):
        acc = 0.0
        for l in range(n):
            acc += L0[i, l] * R[l * m]
        out[i * m] = acc
    for k in range(1, H + 1):
        Li = Lk[k - 1]
        for i in range(n):
            ac = 0.0
            as_ = 0.0
            for l in range(n):
                rc = R[l * m + 2 * k - 1]
                rs = R[l * m + 2 * k]
                ac += Li[i, l] * rc + Li[i, n + l] * rs
                as_ += Li[n + i, l] * rc + Li[n + i, n + l] * rs
            out[i * m + 2 * k - 1] = ac
            out[i * m + 2 * k] = as_


@njit(nogil=True, cache=True)
def active_dofs(A, B):  # pragma: no cover
    """The DOFs a force tangent couples (a row or a column of a nonzero entry)."""
    N, n, _ = A.shape
    on = np.zeros(n, dtype=np.bool_)
    for j in range(N):
        for i in range(n):
            for l in range(n):
                if A[j, i, l] != 0.0 or B[j, i, l] != 0.0:
                    on[i] = True
                    on[l] = True
    return np.nonzero(on)[0]


@njit(nogil=True, cache=True, inline="always")
def _products(c, sn, k, l):  # pragma: no cover
    """``(1/N) sum_j x_j f_k g_l`` for the four products of cos/sin of orders ``k``,
    ``l`` from the sums ``c[q] = (1/N) sum_j x_j cos(q theta_j)`` and ``sn`` (sin):
    (cos cos, cos sin, sin cos, sin sin)."""
    d = abs(k - l)
    sg = 1.0 if k >= l else -1.0
    cc = 0.5 * (c[d] + c[k + l])
    ss = 0.5 * (c[d] - c[k + l])
    cs = 0.5 * (sn[k + l] - sg * sn[d])
    sc = 0.5 * (sn[k + l] + sg * sn[d])
    return cc, cs, sc, ss


@njit(nogil=True, cache=True)
def coupling(act, A, B, E, D, W):  # pragma: no cover
    """``Ga``: the harmonics of the force tangents between the active DOFs ``act``
    (layout ``a * m + p``), the part of the balance's Jacobian beyond the linear
    rotor's (``J = L - U Ga U^T``).

    Each block is the Galerkin product ``W_p sum_j e_p (a_j e_r + b_j d_r)``, written
    through the tangents' own harmonics up to order ``2H`` (products of two orders
    up to ``H``): exact on the ``N > 4H`` instants, and a tenth of the direct sum's
    work.
    """
    N, m = E.shape
    H = (m - 1) // 2
    nu = D[0, 2] if H > 0 else 0.0  # d/dt sin(nu t) at t = 0
    na = act.shape[0]
    G = np.zeros((na * m, na * m))
    ca = np.empty(2 * H + 1)
    sa = np.empty(2 * H + 1)
    cb = np.empty(2 * H + 1)
    sb = np.empty(2 * H + 1)
    ct = np.empty((N, 2 * H + 1))
    st = np.empty((N, 2 * H + 1))
    for j in range(N):
        th = 2.0 * math.pi * j / N
        for q in range(2 * H + 1):
            ct[j, q] = math.cos(q * th)
            st[j, q] = math.sin(q * th)
    for ai in range(na):
        i = act[ai]
        for al in range(na):
            l = act[al]
            nonzero = False
            for j in range(N):
                if A[j, i, l] != 0.0 or B[j, i, l] != 0.0:
                    nonzero = True
                    break
            if not nonzero:
                continue
            for q in range(2 * H + 1):
                ca[q] = 0.0
                sa[q] = 0.0
                cb[q] = 0.0
                sb[q] = 0.0
            for j in range(N):
                a, b = A[j, i, l], B[j, i, l]
                for q in range(2 * H + 1):
                    ca[q] += a * ct[j, q]
                    sa[q] += a * st[j, q]
                    cb[q] += b * ct[j, q]
                    sb[q] += b * st[j, q]
            for q in range(2 * H + 1):
                ca[q] /= N
                sa[q] /= N
                cb[q] /= N
                sb[q] /= N
            row0, col0 = ai * m, al * m
            for k in range(H + 1):
                for ll in range(H + 1):
                    acc_, acs, asc, ass = _products(ca, sa, k, ll)
                    bcc, bcs, bsc, bss = _products(cb, sb, k, ll)
                    w = ll * nu
                    # rows: cos k (p = 2k - 1, or 0 for k = 0), sin k (p = 2k)
                    # columns: cos l (r = 2l - 1 or 0): a cos l - b l nu sin l
                    #          sin l (r = 2l):          a sin l + b l nu cos l
                    pc = 0 if k == 0 else 2 * k - 1
                    rc = 0 if ll == 0 else 2 * ll - 1
                    G[row0 + pc, col0 + rc] += W[pc] * N * (acc_ - w * bcs)
                    if ll > 0:
                        G[row0 + pc, col0 + 2 * ll] += W[pc] * N * (acs + w * bcc)
                    if k > 0:
                        G[row0 + 2 * k, col0 + rc] += W[2 * k] * N * (asc - w * bss)
                        if ll > 0:
                            G[row0 + 2 * k, col0 + 2 * ll] += W[2 * k] * N * (ass + w * bsc)
    return G


@njit(nogil=True, cache=True)
def condensed(act, G, L0, Lk):  # pragma: no cover
    """``I - Ga Sa``, ``Sa`` the linear rotor's inverse dynamic stiffness between the
    active DOFs (block-diagonal by harmonic)."""
    n = L0.shape[0]
    H = Lk.shape[0]
    m = 2 * H + 1
    na = act.shape[0]
    S = np.zeros((na * m, na * m))
    for ai in range(na):
        for al in range(na):
            i, l = act[ai], act[al]
            S[ai * m, al * m] = L0[i, l]
            for k in range(1, H + 1):
                Li = Lk[k - 1]
                S[ai * m + 2 * k - 1, al * m + 2 * k - 1] = Li[i, l]
                S[ai * m + 2 * k - 1, al * m + 2 * k] = Li[i, n + l]
                S[ai * m + 2 * k, al * m + 2 * k - 1] = Li[n + i, l]
                S[ai * m + 2 * k, al * m + 2 * k] = Li[n + i, n + l]
    out = -(G @ S)
    for r in range(na * m):
        out[r, r] += 1.0
    return out


@njit(nogil=True, cache=True)
def _step(R, L0, Lk, act, G, Minv, Mmat, x):  # pragma: no cover
    """The Newton step ``x = J^-1 R`` by the Woodbury identity: ``x0 = L^-1 R``, then
    ``(I - Ga Sa) y = Ga x0_a`` and ``x = x0 + L^-1 U y``. ``Minv`` (the inverse of
    ``I - Ga Sa``) is used where given (a chord step), else ``Mmat`` is solved."""
    m = 2 * Lk.shape[0] + 1
    na = act.shape[0]
    _apply_linear_inverse(L0, Lk, R, x)
    if na == 0:
        return
    xa = np.empty(na * m)
    for ai in range(na):
        for p in range(m):
            xa[ai * m + p] = x[act[ai] * m + p]
    rhs = G @ xa
    if Minv.shape[0] == na * m:
        y = Minv @ rhs
    else:
        y = np.linalg.solve(Mmat, rhs)
    full = np.zeros(x.shape[0])
    for ai in range(na):
        for p in range(m):
            full[act[ai] * m + p] = y[ai * m + p]
    back = np.empty(x.shape[0])
    _apply_linear_inverse(L0, Lk, full, back)
    for r in range(x.shape[0]):
        x[r] += back[r]


@njit(nogil=True, cache=True)
def _imbalance(z, t, E, D, W, H, omega, M, CG, K, fg, unb, brg, eparams, n_cage, Kb,
               tangents, Q, V, F, A, B, R, scale):  # pragma: no cover
    """The forces (and, with ``tangents``, their tangents) at ``z``, the residual ``R``,
    and its largest entry over ``scale`` (inf where it is not finite)."""
    forces(z, t, E, D, omega, fg, unb, brg, eparams, n_cage, Kb, tangents, Q, V, F, A, B)
    residual(z, omega, H, M, CG, K, F, E, W, R)
    worst = 0.0
    for r in range(R.shape[0]):
        a = abs(R[r])
        if not a <= 1e300:  # NaN or overflow
            return np.inf
        worst = max(worst, a)
    return worst / scale


@njit(nogil=True, cache=True)
def solve(z0, act0, G0, Minv0, t, E, D, W, omega, M, CG, K, fg, unb, brg, eparams,
          n_cage, Kb, scale, tol, max_iter, keep):  # pragma: no cover
    """The balance ``R(z) = 0`` from ``z0`` (``K`` the rotor's stiffness with the
    bearings' ``Kb``, which the forces take back): chord steps with a nearby solution's
    Jacobian (``act0``, ``G0``, ``Minv0``; empty: none) while each cuts the imbalance
    to ``CHORD_RATE`` of what it was, then Newton's method, its step halved while it
    does not reduce the imbalance.

    Returns ``(z, act, G, Minv, iterations, imbalance, status)``: with ``keep``, the
    condensed Jacobian at the solution (for a later balance's chord steps); ``status``
    0 converged, 1 stalled, 2 out of iterations.
    """
    N, m = E.shape
    n = fg.shape[0]
    H = (m - 1) // 2
    Q = np.empty((N, n))
    V = np.empty((N, n))
    F = np.empty((N, n))
    A = np.empty((N, n, n))
    B = np.empty((N, n, n))
    R = np.empty(n * m)
    x = np.empty(n * m)
    L0, Lk = linear_inverses(omega, H, M, CG, K)
    z = z0.copy()
    it = 0
    res = _imbalance(z, t, E, D, W, H, omega, M, CG, K, fg, unb, brg, eparams,
                     n_cage, Kb, False, Q, V, F, A, B, R, scale)
    none = np.empty((0, 0))
    if Minv0.shape[0] > 0:
        while res > tol and it < max_iter:
            _step(R, L0, Lk, act0, G0, Minv0, none, x)
            trial = z - x
            new = _imbalance(trial, t, E, D, W, H, omega, M, CG, K, fg, unb, brg,
                             eparams, n_cage, Kb, False, Q, V, F, A, B, R, scale)
            it += 1
            if not new < CHORD_RATE * res:
                res = _imbalance(z, t, E, D, W, H, omega, M, CG, K, fg, unb, brg,
                                 eparams, n_cage, Kb, False, Q, V, F, A, B, R, scale)
                break
            z = trial
            res = new
        if res <= tol and not keep:
            return z, act0, G0, Minv0, it, res, 0
    act = act0
    G = G0
    while res > tol and it < max_iter:
        _imbalance(z, t, E, D, W, H, omega, M, CG, K, fg, unb, brg, eparams, n_cage,
                   Kb, True, Q, V, F, A, B, R, scale)
        act = active_dofs(A, B)
        G = coupling(act, A, B, E, D, W)
        Mmat = condensed(act, G, L0, Lk)
        _step(R, L0, Lk, act, G, none, Mmat, x)
        new = np.inf
        trial = z
        for _ in range(8):
            trial = z - x
            new = _imbalance(trial, t, E, D, W, H, omega, M, CG, K, fg, unb, brg,
                             eparams, n_cage, Kb, False, Q, V, F, A, B, R, scale)
            if new < res:
                break
            for r in range(n * m):
                x[r] *= 0.5
        it += 1
        if not new < res:
            return z, act, G, none, it, res, 1
        z = trial
        res = new
    status = 0 if res <= tol else 2
    if keep and status == 0:
        _imbalance(z, t, E, D, W, H, omega, M, CG, K, fg, unb, brg, eparams, n_cage,
                   Kb, True, Q, V, F, A, B, R, scale)
        act = active_dofs(A, B)
        G = coupling(act, A, B, E, D, W)
        return z, act, G, np.linalg.inv(condensed(act, G, L0, Lk)), it, res, 0
    return z, act, G, none, it, res, status


@njit(nogil=True, cache=True)
def cage_forces(Q, brg, n_cage):  # pragma: no cover
    """Each bearing's force (N) on its journal at the displacements ``Q`` (N, n) with
    the cage at ``n_cage`` angles ``2 pi s / (n_balls n_cage)`` across one ball pitch:
    shape ``(N, n_cage, 2 bearings, 2)``."""
    N = Q.shape[0]
    expo, nb = brg[2], int(brg[3])
    cs, ss = ball_pitch(nb)
    out = np.empty((N, n_cage, 2, 2))
    for j in range(N):
        for b in range(2):
            ix, iy, hx, hy, kB, gamma, x, y = _journal(Q, j, brg, b)
            for s in range(n_cage):
                th = 2.0 * math.pi * s / (nb * n_cage)
                out[j, s, b, 0], out[j, s, b, 1] = bearing_force_at(
                    x, y, math.cos(th), math.sin(th), cs, ss, kB, gamma, expo, nb)
    return out


@njit(nogil=True, cache=True)
def largest_extra_force(z, t, E, D, omega, eparams, q_static, inflate):  # pragma: no cover
    """The largest force (N, N m) the force program ``eparams`` exerts on the orbit
    ``z`` at the instants ``t``, the orbit's excursion from ``q_static`` enlarged by
    the factor ``inflate`` (a margin: a contact the orbit only just clears counts)."""
    N, m = E.shape
    n = q_static.shape[0]
    q = np.empty(n)
    v = np.empty(n)
    f = np.empty(n)
    worst = 0.0
    for j in range(N):
        for i in range(n):
            a = 0.0
            b = 0.0
            for p in range(m):
                a += E[j, p] * z[i * m + p]
                b += D[j, p] * z[i * m + p]
            q[i] = q_static[i] + inflate * (a - q_static[i])
            v[i] = inflate * b
            f[i] = 0.0
        builtin_forces(t[j], omega * t[j], omega, 0.0, q, v, eparams, f)
        for i in range(n):
            worst = max(worst, abs(f[i]))
    return worst
