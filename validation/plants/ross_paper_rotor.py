"""The paper's rotor as a ROSS finite-element model: a plant that shares no simulation
code with ``sknarx.rotor``.

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
  rigid ``DiskElement``s; the paper's disk dampers ``c_d1``, ``c_d2`` as viscous dampers
  from each disk to the frame (bearing elements without stiffness), ``c_a``, ``c_b``
  in the bearings; the joint dampers have no place in a shaft of beam elements;
* ball bearings with Hertzian contact and radial clearance, written here from the
  paper's equations: ball j at the cage angle ``w_c t + 2 pi j / Nb`` pushes with
  ``kB max(delta_j, 0)^1.5``; their stiffness linearised about the static load goes
  into ROSS's ``BearingElement`` (with the paper's damping), the rest enters through
  ROSS's ``add_to_RHS`` force hook;
* each bearing sits in a pedestal with its own mass (ROSS ``PointMass``, 15 kg) on a
  support ``BearingElement`` (1e9 N/m, 5 % damping of the pedestal mode); the journal
  probes read journal minus pedestal;
* gravity on the whole mass matrix, unbalance forces at both disks.

Faults are ROSS's own (``ross.faults``): the Mayes breathing crack on a shaft element
(Papadopoulos' compliance coefficients), the flexible-coupling misalignment
(``MisalignmentFlex``, combined parallel and angular) on the element at a bearing, and
``Rubbing`` at a disk's element; their forces enter through the same hook. (ROSS's
crack keeps only the diagonal of its stiffness turned into the fixed frame, so it
has no coupling between the planes; ``crack_form="rotated"`` keeps it.) ROSS has
no joint looseness, and the joint element here (a flange, ~8e10 N/m) is far too stiff
to switch explicitly through the force hook (tried: Newton fails in the first step), so
this family draws none; support anisotropy is the pedestal's stiffness per direction.

Integrated by ROSS (Newmark, pseudo-modal reduction to 40 modes), settled at each
speed, sampled at the measurement rate, and returned in the gap diagnosis's
measured-file format. 40 modes, not ROSS's usual handful: a soft pedestal's motion
needs them (soft x pedestals of 6.08e6 N/m at 146.6 rad/s, 1x effect-on over
effect-off: with 16 modes xB 0.55, xA 0.99, xO1 0.99; with 24, 40 and 60 modes xB 0.90,
0.913, 0.913, xA 0.88, xO1 0.91 -- a 16-mode basis invents a bearing-B signature;
nominal sweeps change by under 1 %, at the same cost).

With the disk dampers the plant is stable over 81.7-276.5 rad/s
(without them every shaft mode is nearly undamped -- the bearings barely move -- and
the integration diverged at 125 rad/s); disks' 1x peaks near 136-147 rad/s at 1.0 mm
(sknarx: 1.05 mm at 150 rad/s; the paper: 144.5 rad/s); about 1 s per speed step
with 1 s of settling and 5 Newmark substeps per 1 kHz sample.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

E_STEEL, RHO_STEEL, G_STEEL = 2.11e11, 7810.0, 8.12e10

# stations along the shaft, m; nodes: A=0, O1=3, O2=4, B=7; pedestals 8 (A) and 9 (B)
_NODES = np.array([0.0, 0.29 / 3, 2 * 0.29 / 3, 0.29, 0.31, 0.31 + 0.59 / 3,
                   0.31 + 2 * 0.59 / 3, 0.90])
NODE = {"A": 0, "O1": 3, "O2": 4, "B": 7}
PEDESTAL = {"A": 8, "B": 9}
#: shaft elements: a crack station's middle element, a disk's element, a bearing's
CRACK_ELEMENT = {"A-O1": 1, "O2-B": 5}
RUB_ELEMENT = {"O1": 3, "O2": 4}
COUPLING_ELEMENT = {"A": 0, "B": 6}


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
    c_a: float = 3000.0  # N s/m, in bearing A
    c_b: float = 3000.0
    c_d1: float = 3000.0  # N s/m, disk O1 to the frame
    c_d2: float = 3000.0
    kB_A: float = 13.34e9  # N/m^1.5
    kB_B: float = 13.34e9
    clearance: float = 0.5e-6  # m, radial
    n_balls: int = 8
    R_outer: float = 63.9e-3
    r_inner: float = 40.1e-3
    e_O1: float = 0.6e-3  # m, disk eccentricity
    e_O2: float = 0.6e-3
    phase_O1: float = 0.0
    phase_O2: float = np.pi / 4
    m_pedestal: float = 15.0
    k_pedestal: tuple = (1e9, 1e9)  # N/m, (x, y), both pedestals
    zeta_pedestal: float = 0.05
    gravity: float = 9.81
    faults: dict = field(default_factory=dict)
    #: "as-written": ROSS 2.3's Mayes crack, which keeps only the diagonal of the
    #: cracked element's stiffness turned into the fixed frame; "rotated": the same crack
    #: (ROSS's compliances, element and breathing) with the off-diagonal term kept
    #: (see ``_crack_class``)
    crack_form: str = "as-written"


def _crack_class(form="as-written"):
    """ROSS's crack with its compliance table read by ``json``: ROSS 2.3 parses the
    table's "[value, depth]" strings with ``pandas.eval`` on a Series, which pandas 3
    refuses; the coefficients and the model are ROSS's.

    ``form="rotated"`` keeps the term ROSS drops. ROSS's Mayes crack turns the cracked
    element's stiffness from the crack's frame into the fixed one, ``K = T^T diag(k_xi,
    k_eta) T``, and then builds the element from ``K[0, 0]`` and ``K[1, 1]`` alone; the
    off-diagonal ``K[0, 1] = (k_xi - k_eta) sin cos`` -- the coupling between the two
    planes that a crack turning with the shaft has in the fixed frame -- is dropped, so
    a crack loaded by the static (vertical) deflection pushes almost nothing
    horizontally. The rotated form adds it on the element's translational degrees of
    freedom, with ROSS's own maps from the crack's cantilever to the element's ends.
    """
    import json

    from ross.faults.crack import Crack

    if form not in ("as-written", "rotated"):
        raise ValueError(f"crack_form must be 'as-written' or 'rotated', not {form!r}")

    class _Crack(Crack):
        def _get_coefficient(self, coeff):
            c = np.array([json.loads(v) for v in self.coefficient_data[coeff]])
            ind = np.where(c[:, 1] >= self.depth_ratio * 2)[0]
            nu, E = self.shaft_elem.material.Poisson, self.shaft_elem.material.E
            return c[ind[0], 0] * (1 - nu**2) / (E * (self.shaft_elem.odl / 2) ** 3)

    if form == "as-written":
        return _Crack

    class _RotatedCrack(_Crack):
        def mayes(self, ap):
            # ROSS's own element (it keeps K[0,0] and K[1,1] of the fixed-frame
            # stiffness), plus the off-diagonal term it drops:
            # (k_xi - k_eta) sin(ap) cos(ap), with ROSS's breathing k_xi, k_eta
            K = super().mayes(ap)
            ko, kcx, kcz = self.Ko[0, 0], self.Kc[0, 0], self.Kc[1, 1]
            k_xi = 0.5 * (ko + kcx) + 0.5 * (ko - kcx) * np.cos(ap)
            k_eta = 0.5 * (ko + kcz) + 0.5 * (ko - kcz) * np.cos(ap)
            k_xy = (k_xi - k_eta) * np.sin(ap) * np.cos(ap)
            # ROSS's maps (its Toxy, Toyz) of the cantilever's tip displacement to the
            # element's (x, theta_y) and (y, theta_x) ends, at DOFs 0, 4, 6, 10 and
            # 1, 3, 7, 9 of its 12
            L = self.shaft_elem.L
            coupling = k_xy * np.outer([-1.0, -L, 1.0, 0.0], [-1.0, L, 1.0, 0.0])
            ix, iy = [0, 4, 6, 10], [1, 3, 7, 9]
            K[np.ix_(ix, iy)] += coupling
            K[np.ix_(iy, ix)] += coupling.T
            return K

    return _RotatedCrack


def _diameter(k, L, factor):
    """Solid shaft diameter whose beam stiffness ``factor E I / L^3`` is ``k``."""
    inertia = k * L**3 / (factor * E_STEEL)
    return (64 * inertia / np.pi) ** 0.25


def _hertz(x, y, cage_angle, kB, clearance, n_balls):
    """Ball-bearing contact force (N) on the journal at (x, y), m, from its housing."""
    th = cage_angle + 2 * np.pi * np.arange(n_balls) / n_balls
    d = x * np.cos(th) + y * np.sin(th) - clearance
    f = kB * np.clip(d, 0.0, None) ** 1.5
    return -np.array([np.sum(f * np.cos(th)), np.sum(f * np.sin(th))])


def _static_stiffness(load, kB, p):
    """Tangent stiffness (N/m) of a bearing carrying ``load`` (N, the weight on it), at
    the journal's static deflection, averaged over the cage angle."""
    from scipy.optimize import brentq

    def fy(y):
        return np.mean([_hertz(0.0, y, a, kB, p.clearance, p.n_balls)[1]
                        for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)])

    y0 = brentq(lambda y: fy(y) - load, -1e-3, -p.clearance)
    h = 1e-9
    return -(fy(y0 + h) - fy(y0 - h)) / (2 * h)  # the support stiffens downward


class RossPlant:
    """The ROSS rotor, its bearings, faults and how to run a stepped sweep on it."""

    def __init__(self, params: PaperRotorROSS | None = None, n_modes: int = 40):
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
            masses = [rs.PointMass(n=PEDESTAL[b], m=p.m_pedestal) for b in ("A", "B")]
            kpx, kpy = p.k_pedestal
            cpx = 2 * p.zeta_pedestal * np.sqrt(kpx * p.m_pedestal)
            cpy = 2 * p.zeta_pedestal * np.sqrt(kpy * p.m_pedestal)
            supports = [rs.BearingElement(n=PEDESTAL[b], kxx=kpx, kyy=kpy, cxx=cpx,
                                          cyy=cpy, tag=f"pedestal_{b}") for b in ("A", "B")]
            # static load per bearing from the rotor's weight (two supports: statically
            # determinate, moments about bearing A)
            probe = rs.Rotor(shaft, disks, [rs.BearingElement(n=NODE[b], kxx=1e8, cxx=0.0)
                                            for b in ("A", "B")])
            M = probe.M(0)
            nd = probe.number_dof
            w_shaft = p.gravity * M[:, 1::nd].sum(axis=1)[1::nd]  # per shaft node, N
            z = _NODES
            total = w_shaft.sum()
            load_b = float(np.sum(w_shaft * z) / z[-1])
            self.load = {"A": total - load_b, "B": load_b}
            kB = {"A": p.kB_A, "B": p.kB_B}
            self.kB = kB
            self.k_lin = {b: _static_stiffness(self.load[b], kB[b], p) for b in ("A", "B")}
            c_brg = {"A": p.c_a, "B": p.c_b}
            brg = [rs.BearingElement(n=NODE[b], n_link=PEDESTAL[b], kxx=self.k_lin[b],
                                     cxx=c_brg[b], tag=f"bearing_{b}") for b in ("A", "B")]
            # the paper's disk dampers read as viscous dampers from each disk to the frame
            brg += [rs.BearingElement(n=NODE[d], kxx=0.0, cxx=c, tag=f"damper_{d}")
                    for d, c in (("O1", p.c_d1), ("O2", p.c_d2)) if c > 0]
            self.rotor = rs.Rotor(shaft, disks, brg + supports, masses)
        self.nd = self.rotor.number_dof
        self.ped_dof = {b: self.rotor.point_mass_elements[i].dof_global_index[f"x_{PEDESTAL[b]}"]
                        for i, b in enumerate(("A", "B"))}
        self.n_modes = n_modes
        self.diameters_m = {"A-O1": d1, "joint": dj, "O2-B": d2}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.gravity_force = np.asarray(self.rotor.gravitational_force(), dtype=float)
        self.faults = self._make_faults()

    def _make_faults(self):
        """ROSS's fault objects from ``p.faults``."""
        from ross.faults.misalignment import MisalignmentFlex
        from ross.faults.rubbing import Rubbing

        f, out = self.p.faults, {}
        _Crack = _crack_class(self.p.crack_form)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if "crack" in f:
                c = f["crack"]
                out["crack"] = (_Crack(self.rotor, n=CRACK_ELEMENT[c["station"]],
                                      depth_ratio=c["depth"], crack_model="Mayes"), c["angle"])
            if "rub" in f:
                r = f["rub"]
                out["rub"] = Rubbing(self.rotor, n=RUB_ELEMENT[r["at"]],
                                     distance=r["clearance"], contact_stiffness=r["stiffness"],
                                     contact_damping=1.0, friction_coeff=r["friction"])
            if "misalignment" in f:
                m = f["misalignment"]
                # a flexible coupling of 5e5 N/m radial and 4.5e5 N m/rad bending stiffness
                out["misalignment"] = MisalignmentFlex(
                    self.rotor, n=COUPLING_ELEMENT[m["at"]], mis_type="combined",
                    mis_distance_x=m["parallel"] / np.sqrt(2),
                    mis_distance_y=m["parallel"] / np.sqrt(2), mis_angle=m["angular"],
                    radial_stiffness=5e5, bending_stiffness=4.5e5)
            if "looseness" in f:
                raise ValueError("the ROSS plant has no joint looseness (see UNSUPPORTED "
                                 "in plants.families)")
        return out

    def _shaft_angle(self, w, t):
        """Shaft angle (rad) and squared speed ((rad/s)^2) at times ``t``."""
        sf = self.p.faults.get("speed-fluctuation")
        if sf is None:
            return w * t, np.full_like(t, w * w)
        a, wf = sf["amplitude"], 2 * np.pi * sf["frequency_hz"]
        ph = sf.get("phase", 0.0)  # where the ripple stands when the record starts
        # the angle is the speed's integral from t = 0, where it is zero
        return (w * t + a * w / wf * (np.sin(wf * t + ph) - np.sin(ph)),
                (w * (1 + a * np.cos(wf * t + ph))) ** 2)

    def _forces(self, w, t):
        p, nd = self.p, self.nd
        phi, w2 = self._shaft_angle(w, t)
        F = np.tile(self.gravity_force, (t.size, 1))
        for node, e, ph in ((NODE["O1"], p.e_O1, p.phase_O1), (NODE["O2"], p.e_O2, p.phase_O2)):
            f = p.m_disk * e * w2
            F[:, nd * node] += f * np.cos(phi + ph)
            F[:, nd * node + 1] += f * np.sin(phi + ph)
        if "thermal-bow" in p.faults:  # a bowed segment A-O1: a rotating force k1 * bow
            b = p.faults["thermal-bow"]
            F[:, nd * NODE["O1"]] += p.k1 * b["bow"] * np.cos(phi + b["angle"])
            F[:, nd * NODE["O1"] + 1] += p.k1 * b["bow"] * np.sin(phi + b["angle"])
        if "gear-mesh" in p.faults:  # a mesh force at 7x on disk O2
            g = p.faults["gear-mesh"]
            F[:, nd * NODE["O2"]] += g["force"] * np.cos(7 * phi + g["angle"])
            F[:, nd * NODE["O2"] + 1] += g["force"] * np.sin(7 * phi + g["angle"])
        if "cage-fault" in p.faults:  # a force turning with the cage in bearing A or B,
            # between journal and pedestal as the balls' own forces are
            c = p.faults["cage-fault"]
            cage = p.r_inner / (p.R_outer + p.r_inner) * phi
            fx, fy = c["force"] * np.cos(cage + c["angle"]), c["force"] * np.sin(cage + c["angle"])
            i, j = nd * NODE[c["at"]], self.ped_dof[c["at"]]
            F[:, i] += fx
            F[:, i + 1] += fy
            F[:, j] -= fx
            F[:, j + 1] -= fy
        if "misalignment" in self.faults:
            F += self.faults["misalignment"].compute_reaction_force(phi).T
        return F, phi

    def run(self, w, fs=1000.0, n_samples=1000, settle=1.0, substeps=5):
        """Settled record at speed ``w`` (rad/s): ``t`` (s) and each probe's reading (m)."""
        p, nd = self.p, self.nd
        dt = 1.0 / (fs * substeps)
        n_settle = int(round(settle * fs)) * substeps
        t = (np.arange(n_settle + n_samples * substeps) - n_settle) * dt
        F, phi = self._forces(w, t)
        # gravity and unbalance faded in over the first part of the settling time, so
        # the integrator does not start with the whole weight on a journal at rest
        ramp = np.clip((t - t[0]) / (0.3 * max(settle, 1e-9)), 0.0, 1.0)
        F = F * (ramp * ramp * (3 - 2 * ramp))[:, None]
        cage = p.r_inner / (p.R_outer + p.r_inner) * phi
        ix = {b: NODE[b] * nd for b in ("A", "B")}
        faults = self.faults
        for name in ("crack", "rub"):
            if name in faults:
                obj = faults[name][0] if name == "crack" else faults[name]
                obj.forces = np.zeros((self.rotor.ndof, t.size))

        def rhs(step, time_step=None, disp_resp=None, velc_resp=None, accl_resp=None):
            out = np.zeros(disp_resp.shape[0])
            for b in ("A", "B"):
                i, j = ix[b], self.ped_dof[b]
                x = disp_resp[i] - disp_resp[j]
                y = disp_resp[i + 1] - disp_resp[j + 1]
                f = _hertz(x, y, cage[step], self.kB[b], p.clearance, p.n_balls)
                # the BearingElement's linear stiffness (the tangent at the static load,
                # there for the integrator's stability) is given back: the net force
                # between journal and pedestal is exactly the Hertzian one
                fx, fy = f[0] + self.k_lin[b] * x, f[1] + self.k_lin[b] * y
                out[i] += fx
                out[i + 1] += fy
                out[j] -= fx
                out[j + 1] -= fy
            if "crack" in faults:
                crack, angle = faults["crack"]
                out += crack._get_force_in_time(step, disp_resp, phi[step] + angle)
            if "rub" in faults:
                out += faults["rub"]._get_force_over_time(step, disp_resp, velc_resp, w)
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
            sub = (self.ped_dof[name], self.ped_dof[name] + 1) if name in PEDESTAL else None
            out["x" + name] = y[:, node * nd] - (y[:, sub[0]] if sub else 0.0)
            out["y" + name] = y[:, node * nd + 1] - (y[:, sub[1]] if sub else 0.0)
        return out

    def sweep(self, speeds, channels, fs=1000.0, n_samples=1000, settle=1.0, **kw):
        """Stepped sweep in the measured-file format (speed, t, channels; m)."""
        import pandas as pd

        parts = []
        for w in speeds:
            r = self.run(float(w), fs, n_samples, settle, **kw)
            parts.append(pd.DataFrame({"speed": float(w), "t": r["t"],
                                       **{c: r[c] for c in channels}}))
        return pd.concat(parts, ignore_index=True)


def ross_sweep(truth, physical, speeds, channels, settle=1.0, plant=None):
    """A blind trial's sweep on the ROSS plant (see :mod:`validation.plants.families`);
    ``plant``: ``PaperRotorROSS`` fields that differ from the family's (e.g. its
    ``crack_form``)."""
    m, p = truth["mismatch"], PaperRotorROSS(**(plant or {}))
    faults = {k: v for k, v in physical.items() if k not in ("clearance", "anisotropy")}
    p = replace(
        p, k1=p.k1 * m["k1"], k2=p.k2 * m["k2"], c_a=p.c_a * m["c_a"], c_b=p.c_b * m["c_b"],
        c_d1=p.c_d1 * m["c_d1"], c_d2=p.c_d2 * m["c_d2"], kB_A=p.kB_A * m["kB_A"],
        kB_B=p.kB_B * m["kB_B"], e_O1=p.e_O1 * m["e_O1"], e_O2=p.e_O2 * m["e_O2"],
        phase_O1=m["unbalance_phase"],
        phase_O2=m["unbalance_phase"] + p.phase_O2 + m["beta_error"], faults=faults)
    if "clearance" in physical:
        p = replace(p, clearance=physical["clearance"]["clearance"])
    if "anisotropy" in physical:
        a = physical["anisotropy"]
        stiff = p.k_pedestal[0]
        p = replace(p, k_pedestal=(a["soft"], stiff) if a["soft_axis"] == "x"
                    else (stiff, a["soft"]))
    return RossPlant(p).sweep(speeds, channels, settle=settle)
