"""Independent check of the linearised model: the same rotor built in ROSS.

ROSS (ross-rotordynamics) is a finite-element rotordynamics code. The lumped
model's shaft segments are propped cantilevers of lateral stiffness k1 = 3 EI/a1^3
(and k2 = 3 EI/b2^3): in ROSS they are massless Euler-Bernoulli elements with
exactly those EI; the bolted joint, far stiffer than the segments, is a stiff
element with EI = k_theta * d; bearing masses are disk elements of negligible
inertia; the ball bearings are linearised about the static equilibrium (our
averaged tangent stiffness). Damping is removed on both sides so the comparison
is of the undamped first forward critical speed (1x crossing).
"""

import warnings

import numpy as np
import pytest

import sknarx.rotor as R
from sknarx.rotor.linear import bearing_stiffness


def _import_ross():
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import ross
    except Exception as exc:  # ROSS also fails at import with incompatible plotly versions
        pytest.skip(f"ROSS not usable here: {exc!s:.80}")
    return ross


def _ross_rotor(rs, P, KA, KB):
    E = 2.1e11
    mat = rs.Material(name="massless_steel", rho=10.0, E=E, G_s=8.1e10)

    def elem(L, EI, n):
        od = (64 * EI / (np.pi * E)) ** 0.25
        return rs.ShaftElement(L=L, idl=0, odl=od, material=mat, n=n, shear_effects=False,
                               rotary_inertia=True, gyroscopic=False)

    d = P.a2 - P.a1
    shafts = [elem(P.a1, P.k1 * P.a1**3 / 3, 0), elem(d, P.k_theta * d, 1),
              elem(P.b2, P.k2 * P.b2**3 / 3, 2)]
    disks = [
        rs.DiskElement(n=1, m=P.m_O1, Id=P.J_diam1, Ip=P.J_polar1),
        rs.DiskElement(n=2, m=P.m_O2, Id=P.J_diam2, Ip=P.J_polar2),
        rs.DiskElement(n=0, m=P.m_A, Id=1e-6, Ip=1e-6),
        rs.DiskElement(n=3, m=P.m_B, Id=1e-6, Ip=1e-6),
    ]
    bearings = [
        rs.BearingElement(n=n, kxx=K[0, 0], kyy=K[1, 1], kxy=K[0, 1], kyx=K[1, 0], cxx=0)
        for n, K in ((0, KA), (3, KB))
    ]
    return rs.Rotor(shafts, disks, bearings)


def test_first_forward_critical_speed_matches_ross_within_1_percent():
    rs = _import_ross()
    P = R.RotorParameters(c_a=0.0, c_b=0.0, c_d1=0.0, c_d2=0.0, c_O1=0.0, c_O2=0.0)
    sim = R.RotorBearingSimulator(P)
    ours = sim.linear_model().critical_speeds(1000.0, whirl="forward")[0]
    q = sim.static_equilibrium()
    KA = bearing_stiffness(q[0], q[1], P)
    KB = bearing_stiffness(q[10], q[11], P)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cs = _ross_rotor(rs, P, KA, KB).run_critical_speed(num_modes=12)
    wn = np.asarray(cs.wn())
    whirl = np.asarray(cs.whirl_direction)
    theirs = wn[np.char.startswith(whirl.astype(str), "Forward")][0]
    print(f"first forward critical speed: sknarx {ours:.4f} rad/s, ROSS {theirs:.4f} rad/s")
    assert abs(ours - theirs) / theirs < 0.01
