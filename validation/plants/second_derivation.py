"""A second derivation of the paper's rotor: a plant written from Jin et al. (2022) and
the fault literature, not from ``sknarx.rotor``.

It takes the other legitimate readings of what the paper leaves open (see
``docs/rotor_model.md`` for the readings ``sknarx.rotor`` took):

* **bearing housings with their own mass** (15 kg each) on pedestals (3e8 N/m,
  5 % damping of the housing mode): the Hertzian ball contact acts between journal and
  housing, the paper's ``ca``/``cb`` act in parallel with it (journal to housing), and
  the journal probes are mounted on the housings (they read journal minus housing, as
  eddy-current probes on a bearing cap do);
* the shaft segments' own mass (steel, diameters from ``k1 = k2 = 3 E I / L^3``),
  lumped half to each end;
* the paper's ``k`` ("bending stiffness of the shaft") read as the shaft through the
  joint *in parallel* with the contact ``kb`` -- one lateral spring ``k + kb`` -- and
  ``k_theta`` the joint's bending spring;
* ``c_d1``, ``c_d2`` read as absolute (disk-to-frame) damping and ``c_O1``, ``c_O2``
  ("damping introduced by the rotation of the disks") as N m s/rad on each disk's
  slopes to the frame;
* the table's "1" µm read as the *radial* clearance (sknarx reads it as the diametral
  one, 0.5 µm radial).

Disk slopes are the coordinates (``psi_x = dx/dz``, ``psi_y = dy/dz``), gyroscopic
moments ``J_p Omega`` couple them so that forward whirl stiffens. Integrated by a
fixed-step fourth-order Runge-Kutta written here (numba), 10 substeps per 1 kHz sample.

Effects, each written from its source (parameters in SI):

* ``crack`` -- breathing crack, Mayes & Davies (1984): the cracked segment's
  stiffness loses ``d_xi`` (normal to the crack front) and ``d_eta`` of its value in the
  rotating frame, weighted by ``(1 + cos(phi - psi))/2``; at segment A-O1 or O2-B.
* ``rub`` -- a stator ring around disk O1 or O2 (Muszynska, *Rotordynamics*, 2005):
  radial contact ``k_r (r - c_r)`` beyond the clearance and Coulomb friction
  ``mu`` times the normal force against the surface's motion.
* ``misalignment`` -- a flexible coupling at bearing A's or B's end whose halves are
  offset by ``delta`` (Sekhar & Prabhu, 1995): a reaction ``K_c delta`` at twice the
  running speed plus its static part.
* ``looseness`` -- the bolted joint loses its preload beyond an opening ``gap`` (m):
  joint lateral and bending stiffness (the shaft through the joint included) drop to
  ``residual`` of their value, force continuous at the opening.
* ``clearance`` -- a larger radial clearance of both ball bearings.
* ``anisotropy`` -- pedestals softer in one direction (``k_px`` != ``k_py``), with the
  housings' mass and damping: a support resonance of its own.
* ``speed-fluctuation`` -- ``Omega (1 + a cos(w_f t + ph))``, ``t`` each record's time
  (the ripple's phase ``ph`` where a record starts).
* out of library: ``thermal-bow`` (a bowed segment A-O1: a rotating force ``k1 bow``),
  ``gear-mesh`` (a mesh force at 7x on disk O2, my own design), ``cage-fault`` (a
  force turning with the cage between journal and housing of bearing A or B: a damaged
  cage carrying the load unevenly, at the cage's order; also my own design).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

E_STEEL, RHO_STEEL = 2.11e11, 7810.0
# DOF indices
XA, YA, XHA, YHA = 0, 1, 2, 3
XO1, YO1, PXO1, PYO1 = 4, 5, 6, 7
XO2, YO2, PXO2, PYO2 = 8, 9, 10, 11
XB, YB, XHB, YHB = 12, 13, 14, 15
NDOF = 16
#: what each measured channel reads: (DOF, DOF subtracted or -1)
PROBES = {"xO1": (XO1, -1), "yO1": (YO1, -1), "xO2": (XO2, -1), "yO2": (YO2, -1),
          "xA": (XA, XHA), "yA": (YA, YHA), "xB": (XB, XHB), "yB": (YB, YHB)}


@dataclass
class SecondRotor:
    """Parameters of the second derivation (SI); defaults are the paper's values."""

    k1: float = 8e5
    k2: float = 8e5
    k: float = 2.5e8
    kb: float = 2.5e7
    k_theta: float = 2.5e7
    c_a: float = 3000.0
    c_b: float = 3000.0
    c_d1: float = 3000.0
    c_d2: float = 3000.0
    c_O1: float = 3000.0
    c_O2: float = 3000.0
    m_journal: float = 20.0
    m_disk: float = 40.0
    J_diam: float = 0.803
    J_polar: float = 1.6059
    a1: float = 0.29
    a2: float = 0.31
    span: float = 0.90
    m_housing: float = 15.0
    k_px: float = 3e8  # pedestal stiffness, N/m
    k_py: float = 3e8
    zeta_housing: float = 0.05
    kB_A: float = 13.34e9  # N/m^1.5, per bearing
    kB_B: float = 13.34e9
    clearance_A: float = 1e-6  # radial, m
    clearance_B: float = 1e-6
    n_balls: int = 8
    R_outer: float = 63.9e-3
    r_inner: float = 40.1e-3
    e_O1: float = 0.6e-3  # eccentricity per disk, m
    e_O2: float = 0.6e-3
    phase_O1: float = 0.0
    phase_O2: float = np.pi / 4
    gravity: float = 9.81
    #: journal probes on the housings (journal minus housing) or on the frame (absolute)
    probes_on_housings: bool = True
    effects: dict = field(default_factory=dict)

    def matrices(self):
        """M, C, K, G (16 x 16) and the constant force vector (gravity), SI."""
        p = self
        M, C, K, G = (np.zeros((NDOF, NDOF)) for _ in range(4))
        b2 = p.span - p.a2
        d = p.a2 - p.a1

        def shaft_mass(k, L):
            # diameter from k = 3 E I / L^3 (pinned in the bearing, clamped in the disk)
            inertia = k * L**3 / (3 * E_STEEL)
            dia = (64 * inertia / np.pi) ** 0.25
            return RHO_STEEL * np.pi * dia**2 / 4 * L

        ms1, ms2 = shaft_mass(p.k1, p.a1), shaft_mass(p.k2, b2)
        for i, m in ((XA, p.m_journal + ms1 / 2), (XO1, p.m_disk + ms1 / 2),
                     (XO2, p.m_disk + ms2 / 2), (XB, p.m_journal + ms2 / 2),
                     (XHA, p.m_housing), (XHB, p.m_housing)):
            M[i, i] = M[i + 1, i + 1] = m
        for i in (PXO1, PXO2):
            M[i, i] = M[i + 1, i + 1] = p.J_diam
            # forward whirl stiffens: J_d psi_x'' + J_p W psi_y' ..., J_d psi_y'' - J_p W psi_x'
            G[i, i + 1] = p.J_polar
            G[i + 1, i] = -p.J_polar

        def spring(mat, idx, coef, value):
            v = np.zeros(NDOF)
            v[list(idx)] = coef
            mat += value * np.outer(v, v)

        for plane in (0, 1):  # x-z plane uses x, psi_x; y-z uses y, psi_y
            wA, wO1, sO1 = XA + plane, XO1 + plane, PXO1 + plane
            wO2, sO2, wB = XO2 + plane, PXO2 + plane, XB + plane
            spring(K, (wO1, wA, sO1), (1.0, -1.0, -p.a1), p.k1)
            spring(K, (wO2, wB, sO2), (1.0, -1.0, b2), p.k2)  # B lies at +b2 from O2
            spring(K, (wO2, wO1, sO1, sO2), (1.0, -1.0, -d / 2, -d / 2), p.k + p.kb)
            spring(K, (sO2, sO1), (1.0, -1.0), p.k_theta)
            spring(C, (wA, XHA + plane), (1.0, -1.0), p.c_a)
            spring(C, (wB, XHB + plane), (1.0, -1.0), p.c_b)
            C[wO1, wO1] += p.c_d1
            C[wO2, wO2] += p.c_d2
            C[sO1, sO1] += p.c_O1
            C[sO2, sO2] += p.c_O2
        for h in (XHA, XHB):
            K[h, h] += p.k_px
            K[h + 1, h + 1] += p.k_py
            C[h, h] += 2 * p.zeta_housing * np.sqrt(p.k_px * p.m_housing)
            C[h + 1, h + 1] += 2 * p.zeta_housing * np.sqrt(p.k_py * p.m_housing)
        F0 = np.zeros(NDOF)
        for i in (XA, XO1, XO2, XB, XHA, XHB):
            F0[i + 1] = -M[i, i] * p.gravity
        return M, C, K, G, F0


# effect codes for the kernel (one parameter row each)
_EFFECT_CODES = {"crack": 0, "rub": 1, "misalignment": 2, "looseness": 3,
                 "speed-fluctuation": 4, "thermal-bow": 5, "gear-mesh": 6, "cage-fault": 7}


@njit(cache=True, nogil=True)
def _hertz(dx, dy, cage, kB, gamma, nb, out):  # pragma: no cover
    fx = 0.0
    fy = 0.0
    for j in range(nb):
        th = cage + 2.0 * math.pi * j / nb
        c = math.cos(th)
        s = math.sin(th)
        delta = dx * c + dy * s - gamma
        if delta > 0.0:
            f = kB * delta * math.sqrt(delta)
            fx -= f * c
            fy -= f * s
    out[0] = fx
    out[1] = fy


@njit(cache=True, nogil=True)
def _forces(t, q, v, w, scal, eff, f, ramp):  # pragma: no cover
    """Nonlinear and effect forces (N) at time t; ``scal`` holds the plant's scalars.

    ``ramp`` (0-1) fades the unbalance in while the plant settles.
    """
    k1, k2, a1, b2, d = scal[0], scal[1], scal[2], scal[3], scal[4]
    kjoint, ktheta = scal[5], scal[6]
    kBA, kBB, gA, gB, nb, cage_ratio = scal[7], scal[8], scal[9], scal[10], scal[11], scal[12]
    mO1e, mO2e, phO1, phO2 = scal[13], scal[14], scal[15], scal[16]
    for i in range(f.size):
        f[i] = 0.0
    phi = w * t
    wdot2 = w * w
    for r in range(eff.shape[0]):
        if eff[r, 0] == 4:  # speed fluctuation: Omega (1 + a cos(w_f t + ph))
            a, wf, ph = eff[r, 1], eff[r, 2], eff[r, 3]
            # the shaft angle is the speed's integral from t = 0, where it is zero
            phi = w * t + a * w / wf * (math.sin(wf * t + ph) - math.sin(ph))
            wdot2 = (w * (1.0 + a * math.cos(wf * t + ph))) ** 2
    # unbalance on both disks
    wdot2 *= ramp
    f[XO1] += mO1e * wdot2 * math.cos(phi + phO1)
    f[YO1] += mO1e * wdot2 * math.sin(phi + phO1)
    f[XO2] += mO2e * wdot2 * math.cos(phi + phO2)
    f[YO2] += mO2e * wdot2 * math.sin(phi + phO2)
    # ball bearings between journal and housing
    cage = cage_ratio * phi
    out = np.zeros(2)
    _hertz(q[XA] - q[XHA], q[YA] - q[YHA], cage, kBA, gA, int(nb), out)
    f[XA] += out[0]
    f[YA] += out[1]
    f[XHA] -= out[0]
    f[YHA] -= out[1]
    _hertz(q[XB] - q[XHB], q[YB] - q[YHB], cage, kBB, gB, int(nb), out)
    f[XB] += out[0]
    f[YB] += out[1]
    f[XHB] -= out[0]
    f[YHB] -= out[1]
    for r in range(eff.shape[0]):
        code = eff[r, 0]
        if code == 0:  # breathing crack (Mayes & Davies)
            station, dxi, deta, psi = eff[r, 1], eff[r, 2], eff[r, 3], eff[r, 4]
            if station == 0:
                kk, i_w, i_j, i_s, lever = k1, XO1, XA, PXO1, -a1
            else:
                kk, i_w, i_j, i_s, lever = k2, XO2, XB, PXO2, b2
            ux = q[i_w] - q[i_j] + lever * q[i_s]
            uy = q[i_w + 1] - q[i_j + 1] + lever * q[i_s + 1]
            c = math.cos(phi)
            s = math.sin(phi)
            xi = c * ux + s * uy
            eta = -s * ux + c * uy
            g = 0.5 * (1.0 + math.cos(phi - psi))
            fxi = kk * dxi * g * xi  # the stiffness lost, given back as a force
            feta = kk * deta * g * eta
            fx = c * fxi - s * feta
            fy = s * fxi + c * feta
            f[i_w] += fx
            f[i_w + 1] += fy
            f[i_j] -= fx
            f[i_j + 1] -= fy
            f[i_s] += lever * fx
            f[i_s + 1] += lever * fy
        elif code == 1:  # rub at a disk (stator ring)
            i = XO1 if eff[r, 1] == 0 else XO2
            cr, kr, mu = eff[r, 2], eff[r, 3], eff[r, 4]
            x = q[i]
            y = q[i + 1]
            rr = math.sqrt(x * x + y * y)
            if rr > cr:
                fn = kr * (rr - cr)
                nx, ny = x / rr, y / rr
                # friction against the surface's motion (the shaft turns x -> y)
                f[i] += -fn * nx + mu * fn * ny
                f[i + 1] += -fn * ny - mu * fn * nx
        elif code == 2:  # coupling misalignment at a bearing end (Sekhar & Prabhu)
            i = XA if eff[r, 1] == 0 else XB
            kc_delta, ang = eff[r, 2], eff[r, 3]
            f[i] += 0.5 * kc_delta * math.sin(2.0 * phi + ang)
            f[i + 1] += 0.5 * kc_delta * (1.0 - math.cos(2.0 * phi + ang))
        elif code == 3:  # joint looseness: stiffness lost beyond the opening
            residual, gap = eff[r, 1], eff[r, 2]
            ux = q[XO2] - q[XO1] - 0.5 * d * (q[PXO1] + q[PXO2])
            uy = q[YO2] - q[YO1] - 0.5 * d * (q[PYO1] + q[PYO2])
            u = math.sqrt(ux * ux + uy * uy)
            if u > gap:
                # the linear matrices hold k_joint u; give back what is lost beyond gap
                lost = kjoint * (1.0 - residual) * (u - gap) / u
                fx, fy = lost * ux, lost * uy
                f[XO2] += fx
                f[YO2] += fy
                f[XO1] -= fx
                f[YO1] -= fy
                f[PXO1] -= 0.5 * d * fx
                f[PXO2] -= 0.5 * d * fx
                f[PYO1] -= 0.5 * d * fy
                f[PYO2] -= 0.5 * d * fy
                tx = q[PXO2] - q[PXO1]
                ty = q[PYO2] - q[PYO1]
                lost_t = ktheta * (1.0 - residual) * (u - gap) / u
                f[PXO2] += lost_t * tx
                f[PYO2] += lost_t * ty
                f[PXO1] -= lost_t * tx
                f[PYO1] -= lost_t * ty
        elif code == 5:  # thermal bow of segment A-O1: a rotating force k1 * bow
            bow, ang = eff[r, 1], eff[r, 2]
            f[XO1] += k1 * bow * math.cos(phi + ang)
            f[YO1] += k1 * bow * math.sin(phi + ang)
        elif code == 6:  # gear mesh at 7x on disk O2
            amp, ang = eff[r, 1], eff[r, 2]
            f[XO2] += amp * math.cos(7.0 * phi + ang)
            f[YO2] += amp * math.sin(7.0 * phi + ang)
        elif code == 7:  # cage fault: a force turning with the cage in bearing A or B
            # between journal and housing, as the balls' own forces are
            j, hj = (XA, XHA) if eff[r, 1] == 0 else (XB, XHB)
            amp, ang = eff[r, 2], eff[r, 3]
            fx = amp * math.cos(cage + ang)
            fy = amp * math.sin(cage + ang)
            f[j] += fx
            f[j + 1] += fy
            f[hj] -= fx
            f[hj + 1] -= fy


@njit(cache=True, nogil=True)
def _integrate(Minv, Cw, K, F0, scal, eff, w, t0, h, n_steps, every, out):  # pragma: no cover
    n = K.shape[0]
    q = np.zeros(n)
    v = np.zeros(n)
    f = np.zeros(n)
    kq = np.zeros((4, n))
    kv = np.zeros((4, n))
    qs = np.zeros(n)
    vs = np.zeros(n)
    k_out = 0
    for step in range(n_steps):
        t = t0 + step * h
        for stage in range(4):
            if stage == 0:
                ts = t
                for i in range(n):
                    qs[i] = q[i]
                    vs[i] = v[i]
            else:
                c = 0.5 if stage < 3 else 1.0
                ts = t + c * h
                for i in range(n):
                    qs[i] = q[i] + c * h * kq[stage - 1, i]
                    vs[i] = v[i] + c * h * kv[stage - 1, i]
            # gravity and unbalance fade in over 0.3 s: no start with the whole weight
            # on a journal at rest
            ramp = min(1.0, (ts - t0) / 0.3)
            ramp = ramp * ramp * (3.0 - 2.0 * ramp)
            _forces(ts, qs, vs, w, scal, eff, f, ramp)
            rhs = f + F0 * ramp - Cw @ vs - K @ qs
            acc = Minv @ rhs
            for i in range(n):
                kq[stage, i] = vs[i]
                kv[stage, i] = acc[i]
        for i in range(n):
            q[i] += h / 6.0 * (kq[0, i] + 2 * kq[1, i] + 2 * kq[2, i] + kq[3, i])
            v[i] += h / 6.0 * (kv[0, i] + 2 * kv[1, i] + 2 * kv[2, i] + kv[3, i])
        if (step + 1) % every == 0 and k_out < out.shape[0]:
            for i in range(n):
                out[k_out, i] = q[i]
            k_out += 1
        if not math.isfinite(q[0]) or abs(q[XO1]) > 0.05:
            return step
    return n_steps


class SecondDerivationPlant:
    """Run the second derivation at a speed or over a stepped sweep."""

    def __init__(self, rotor: SecondRotor | None = None):
        self.rotor = rotor or SecondRotor()

    def _effect_rows(self):
        rows = []
        for name, prm in self.rotor.effects.items():
            if name in _EFFECT_CODES:
                rows.append([_EFFECT_CODES[name], *prm] + [0.0] * (5 - len(prm)))
        return np.array(rows, dtype=float).reshape(-1, 6)

    def run(self, w, fs=1000.0, n_samples=1000, settle=1.5, substeps=10):
        """Settled record at ``w`` rad/s: dict of ``t`` (s) and every probe's reading (m)."""
        p = self.rotor
        M, C, K, G, F0 = p.matrices()
        cl_a, cl_b = p.clearance_A, p.clearance_B
        if "clearance" in p.effects:
            cl_a = cl_b = p.effects["clearance"][0]
        kp = p.effects.get("anisotropy")
        if kp is not None:  # pedestal stiffness per direction (both bearings)
            K = K.copy()
            for h in (XHA, XHB):
                K[h, h] += kp[0] - p.k_px
                K[h + 1, h + 1] += kp[1] - p.k_py
        scal = np.array([p.k1, p.k2, p.a1, p.span - p.a2, p.a2 - p.a1, p.k + p.kb,
                         p.k_theta, p.kB_A, p.kB_B, cl_a, cl_b, p.n_balls,
                         p.r_inner / (p.R_outer + p.r_inner), p.m_disk * p.e_O1,
                         p.m_disk * p.e_O2, p.phase_O1, p.phase_O2])
        h = 1.0 / (fs * substeps)
        n_settle = int(round(settle * fs)) * substeps
        n_steps = n_settle + n_samples * substeps
        out = np.zeros((n_steps // substeps, NDOF))
        done = _integrate(np.linalg.inv(M), C + w * G, K, F0, scal, self._effect_rows(), w,
                          -settle, h, n_steps, substeps, out)
        if done < n_steps:
            raise FloatingPointError(f"second-derivation plant diverged at {w:.1f} rad/s")
        rec = out[n_settle // substeps:]
        # sample k is stored after step (k + 1) * substeps; t = 0 is the shaft angle's zero
        res = {"t": np.arange(1, n_samples + 1) / fs}
        for name, (i, j) in PROBES.items():
            rel = j >= 0 and p.probes_on_housings
            res[name] = rec[:, i] - (rec[:, j] if rel else 0.0)
        return res

    def sweep(self, speeds, channels, fs=1000.0, n_samples=1000, settle=1.5):
        """Stepped sweep in the measured-file format (speed, t, channels; m)."""
        import pandas as pd

        parts = []
        for w in speeds:
            r = self.run(float(w), fs, n_samples, settle)
            parts.append(pd.DataFrame({"speed": float(w), "t": r["t"],
                                       **{c: r[c] for c in channels}}))
        return pd.concat(parts, ignore_index=True)
