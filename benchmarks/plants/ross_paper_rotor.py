"""The paper's rotor as a ROSS finite-element model: a plant that shares no simulation
code with ``sknarx.rotor`` (issue #13, family (a)).

A second engineer's reading of Jin et al. (2022), Tables 1-2, built from ROSS elements:

* a solid steel shaft of Timoshenko elements (ROSS ``ShaftElement``: shear, rotary
  inertia, gyroscopics), bearing A at 0, disks O1 at 0.29 m and O2 at 0.31 m, bearing
  B at 0.90 m, three elements per outer segment. The paper gives segment stiffnesses,
  not diameters: each outer segment's diameter is chosen so that a beam simply supported
  at the bearing and clamped in the disk has the paper's k1 = 8e5 N/m (3 E I / L^3),
  and the joint section is a flange as thick as the thicker shaft (stiffer than the
  paper's k + kb as a clamped-clamped beam, 12 E I / L^3) -- one of the readings, not
  sknarx's (which keeps k, kb and k_theta apart);
* the journals' lumped masses (20 kg) and the disks (40 kg, the paper's inertias) as
  rigid ``DiskElement``s;
* ball bearings with Hertzian contact and radial clearance, written here from the
  paper's equations: ball j at the cage angle ``w_c t + 2 pi j / Nb`` pushes with
  ``kB max(delta_j, 0)^1.5``; their stiffness linearised about the static load goes
  into ROSS's ``BearingElement`` (with the paper's damping), the rest enters through
  ROSS's ``add_to_RHS`` force hook;
* gravity on the whole mass matrix, unbalance forces at both disks.

Integrated by ROSS (Newmark, pseudo-modal reduction), settled at each speed, sampled
at the measurement rate, and returned in the gap diagnosis's measured-file format.

Status (2026-11-22, not yet used by a benchmark or a test). Measured: about 3 s per speed
step for 3 s simulated (10 substeps per 1 kHz sample); settled records (decay ratio
1.06-1.29 with 1 s of settling below 210 rad/s). Against ``sknarx.rotor``'s nominal
model at 90/150/210/270 rad/s the 1x differs by 35-180 % (complex) at the disks and
40-170 % at the journals: the disks' 1x peaks near 147 rad/s at 2.5 mm (sknarx: 1.05 mm
at 150 rad/s; the paper reports its first critical at 144.5 rad/s) -- this reading puts
all damping in the bearings, as the paper's shaft and joint dampers have no place in a
shaft of beam elements. At 125 rad/s the
integration diverges about 0.45 s into the settling (the tilt at bearing A grows to
0.02 rad, then explodes within 30 steps) with 10 or 20 substeps, 8, 12, 16 or 24
pseudo-modes, and with or without rotary inertia on the journal masses: the Hertzian
remainder enters ROSS's Newmark explicitly (its Newton iteration holds the right-hand
side fixed within a step), which is the first suspect; a parametric resonance of the
ball-passage stiffness variation (8 x 0.386 x 125 = 386 rad/s, twice a mode near
193 rad/s) is the second. With only 0.5 s of settling (the loads faded in over 0.15 s)
it also fails at 150 rad/s; 2 s works there. The fault models (ROSS's ``run_crack``,
``run_misalignment``, ``run_rubbing``) are not wired in yet.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

E_STEEL, RHO_STEEL, G_STEEL = 2.11e11, 7810.0, 8.12e10

# stations along the shaft, m; nodes: A=0, O1=3, O2=4, B=7
_NODES = np.array([0.0, 0.29 / 3, 2 * 0.29 / 3, 0.29, 0.31, 0.31 + 0.59 / 3,
                   0.31 + 2 * 0.59 / 3, 0.90])
NODE = {"A": 0, "O1": 3, "O2": 4, "B": 7}


@dataclass(frozen=True)
class PaperRotorROSS:
    """Parameters of the ROSS plant (SI units); defaults are the paper's values."""

    k1: float = 8e5  # N/m, segment A-O1 (sets its diameter)
    k2: float = 8e5  # N/m, segment O2-B
    k_joint: float = 2.5e8 + 2.5e7  # N/m, the joint section (k + kb)
    m_journal: float = 20.0
    m_disk: float = 40.0
    J_polar: float = 1.6059
    J_diam: float = 0.803
    c_bearing: float = 3000.0  # N s/m
    kB: float = 13.34e9  # N/m^1.5
    clearance: float = 0.5e-6  # m
    n_balls: int = 8
    R_outer: float = 63.9e-3
    r_inner: float = 40.1e-3
    e: float = 0.6e-3  # m, disk eccentricity
    beta: float = np.pi / 4  # disk O2's unbalance angle, rad
    unbalance_phase: float = 0.0
    gravity: float = 9.81


def _diameter(k, L, factor):
    """Solid shaft diameter whose beam stiffness ``factor E I / L^3`` is ``k``."""
    inertia = k * L**3 / (factor * E_STEEL)
    return (64 * inertia / np.pi) ** 0.25


def _hertz(x, y, cage_angle, p):
    """Ball-bearing contact force (N) on the journal at (x, y), m."""
    th = cage_angle + 2 * np.pi * np.arange(p.n_balls) / p.n_balls
    d = x * np.cos(th) + y * np.sin(th) - p.clearance
    f = p.kB * np.clip(d, 0.0, None) ** 1.5
    return -np.array([np.sum(f * np.cos(th)), np.sum(f * np.sin(th))])


def _static_stiffness(load, p):
    """Tangent stiffness (N/m) of a bearing carrying ``load`` (N, the weight on it), at
    the journal's static deflection, averaged over the cage angle."""
    from scipy.optimize import brentq

    def fy(y):
        return np.mean([_hertz(0.0, y, a, p)[1] for a in np.linspace(0, 2 * np.pi, 16,
                                                                       endpoint=False)])

    y0 = brentq(lambda y: fy(y) - load, -1e-3, -p.clearance)
    h = 1e-9
    return -(fy(y0 + h) - fy(y0 - h)) / (2 * h)  # the support stiffens downward


class RossPlant:
    """The ROSS rotor, its bearings and how to run a stepped sweep on it."""

    def __init__(self, params: PaperRotorROSS | None = None, n_modes: int = 16):
        import ross as rs

        self.p = p = params or PaperRotorROSS()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            steel = rs.Material(name="sknarx_plant_steel", rho=RHO_STEEL, E=E_STEEL,
                                G_s=G_STEEL)
            d1 = _diameter(p.k1, 0.29, 3.0)
            d2 = _diameter(p.k2, 0.59, 3.0)
            # the bolted flange joint is at least as thick as the shafts it joins: its
            # bending stiffness then far exceeds the paper's k + kb, as a flange's does
            dj = max(_diameter(p.k_joint, 0.02, 12.0), d1, d2)
            diam = [d1, d1, d1, dj, d2, d2, d2]
            shaft = [rs.ShaftElement(L=float(b - a), idl=0.0, odl=float(d), material=steel)
                     for a, b, d in zip(_NODES[:-1], _NODES[1:], diam, strict=True)]
            small = dict(Id=0.0, Ip=0.0)  # lumped translational masses, as the paper
            disks = [rs.DiskElement(n=NODE["A"], m=p.m_journal, **small),
                     rs.DiskElement(n=NODE["O1"], m=p.m_disk, Id=p.J_diam, Ip=p.J_polar),
                     rs.DiskElement(n=NODE["O2"], m=p.m_disk, Id=p.J_diam, Ip=p.J_polar),
                     rs.DiskElement(n=NODE["B"], m=p.m_journal, **small)]
            probe = rs.Rotor(shaft, disks, [rs.BearingElement(n=NODE[b], kxx=1e8, cxx=0.0)
                                            for b in ("A", "B")])
            self.nd = probe.number_dof
            M = probe.M(0)
            self.gravity_force = -p.gravity * M[:, 1::self.nd].sum(axis=1)
            # static load per bearing from the rotor's weight (two supports: statically
            # determinate, moments about bearing A)
            fy = -self.gravity_force[1::self.nd]
            total = fy.sum()
            load_b = float(np.sum(fy * _NODES) / _NODES[-1])
            self.load = {"A": total - load_b, "B": load_b}
            # the bearings' tangent stiffness at their static load, for the integrator
            self.k_lin = {b: _static_stiffness(self.load[b], p) for b in ("A", "B")}
            brg = [rs.BearingElement(n=NODE[b], kxx=self.k_lin[b], cxx=p.c_bearing,
                                     kzz=1e8, czz=1e3) for b in ("A", "B")]
            self.rotor = rs.Rotor(shaft, disks, brg)
        self.n_modes = n_modes
        self.diameters_m = {"A-O1": d1, "joint": dj, "O2-B": d2}

    def _forces(self, w, t):
        p, nd = self.p, self.nd
        F = np.tile(self.gravity_force, (t.size, 1))
        for node, ph in ((NODE["O1"], p.unbalance_phase),
                         (NODE["O2"], p.unbalance_phase + p.beta)):
            f = p.m_disk * p.e * w * w
            F[:, nd * node] += f * np.cos(w * t + ph)
            F[:, nd * node + 1] += f * np.sin(w * t + ph)
        return F

    def run(self, w, fs=1000.0, n_samples=1000, settle=2.0, substeps=10, extra=None):
        """Settled record at speed ``w`` (rad/s): dict of ``t`` and the DOF columns, m.

        ``extra(step_time, disp)`` may add forces (N, full DOF vector) for effects.
        """
        p, nd = self.p, self.nd
        dt = 1.0 / (fs * substeps)
        n_settle = int(round(settle * fs)) * substeps
        t = (np.arange(n_settle + n_samples * substeps) - n_settle) * dt
        # gravity and unbalance faded in over the first part of the settling time, so
        # the integrator does not start with the whole weight on a journal at rest
        ramp = np.clip((t - t[0]) / (0.3 * max(settle, 1e-9)), 0.0, 1.0)
        F = self._forces(w, t) * (ramp * ramp * (3 - 2 * ramp))[:, None]
        cage = w * p.r_inner / (p.R_outer + p.r_inner)
        ia, ib = NODE["A"] * nd, NODE["B"] * nd

        def rhs(step, time_step=None, disp_resp=None, velc_resp=None, accl_resp=None):
            out = np.zeros(disp_resp.shape[0])
            tt = t[step]
            for b, i in (("A", ia), ("B", ib)):
                x, y = disp_resp[i], disp_resp[i + 1]
                f = _hertz(x, y, cage * tt, p)
                # the BearingElement's linear stiffness (the tangent at the static load,
                # there for the integrator's stability) is added back: the net force on
                # the journal is exactly the Hertzian one
                out[i] += f[0] + self.k_lin[b] * x
                out[i + 1] += f[1] + self.k_lin[b] * y
            if extra is not None:
                out += extra(tt, disp_resp)
            return out

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = self.rotor.run_time_response(
                # ROSS's Newmark iterates to an absolute force residual (default 1e-6 N);
                # with kN of weight and unbalance that sits below round-off at some speeds
                w, F, t - t[0], method="newmark", add_to_RHS=rhs, tol=1e-4,
                model_reduction={"method": "pseudomodal", "num_modes": self.n_modes})
        y = res.yout[n_settle::substeps]
        out = {"t": t[n_settle::substeps]}
        for name, node in NODE.items():
            out["x" + name] = y[:, node * nd]
            out["y" + name] = y[:, node * nd + 1]
        return out

    def sweep(self, speeds, channels, fs=1000.0, n_samples=1000, settle=2.0, **kw):
        """Stepped sweep in the measured-file format (speed, t, channels; m)."""
        import pandas as pd

        parts = []
        for w in speeds:
            r = self.run(float(w), fs, n_samples, settle, **kw)
            parts.append(pd.DataFrame({"speed": float(w), "t": r["t"],
                                       **{c: r[c] for c in channels}}))
        return pd.concat(parts, ignore_index=True)
