"""The order model of a linear rotor at one probe, and its fit to a Bode record.

Model of the measured 1x vector at speed ``w``:
``X(w) = U1 H1(w; p) + U2 H2(w; p) [+ R]`` with ``H_j`` the response at the probe
to a unit unbalance at disk j, ``U_j`` the (unknown, complex) residual unbalances,
``R`` a slow-roll runout vector and ``p`` the bearing parameters. For given ``p``
the unknowns enter linearly (real-linearly in a run-up, where the acceleration
breaks the rotational symmetry) and are solved in closed form (variable
projection); ``p`` is fitted by least squares from several starts.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.optimize import least_squares

from .._progress import evaluated
from ..rotor.runup import runup_order_response, transient_end_rpm
from .records import RPM

__all__ = ["Candidate", "OrderModel", "TRANSIENT_TOL", "complex_pairs", "fit_bearings",
           "predict", "solve_real_linear", "z2_of"]

#: a crossed mode's free vibration below this share of its size counts as died out: a
#: simulation accuracy, half the lumped linear rotor's model-form tolerance
#: (:data:`sknarx.gap.rule.ORDER_DOMAIN_RULE`'s ``rtol``), so the switch from the
#: simulated run-up to the steady response is not seen in a fit
TRANSIENT_TOL = 0.01


class OrderModel:
    """Order model of the rotor at the probe, real-linear in the unbalances.

    ``basis`` returns, per speed bin, the probe's 1x response to a unit unbalance
    at each disk with its heavy spot at the keyphasor and 90 degrees ahead (two
    columns per disk). With ``runup`` (see :func:`runup_rate`) the bins come from an
    order-tracked simulation of the run-up at the measured rate up to the speed where
    the free vibration of every crossed mode of *this* rotor has decayed below
    ``TRANSIENT_TOL`` (:func:`~sknarx.rotor.runup.transient_end_rpm`); above it (and
    without ``runup``) from steady-state responses, which are then exact to that level.
    ``rtol``: the share of its size to which the model's 1x is trusted (the fits'
    weights and :func:`z2_of`).
    """

    def __init__(self, rotor, probe, runup=None, rtol=0.02):
        self.rotor = rotor
        self.probe = probe
        self.runup = runup
        self.rtol = rtol  # the 1x's model-form tolerance, a share of its size

    def basis(self, speeds, kx, ky, cx, cy, angle=0.0):
        """Probe response to unit unbalances; the probe reads the displacement along
        ``angle`` (rad) from the support's x principal axis."""
        r = self.rotor.with_bearings(kxx=kx, kyy=ky, cxx=cx, cyy=cy)
        speeds = np.asarray(speeds, dtype=float)
        XY = r.probe_responses(speeds, self.probe["position"])
        H = np.cos(angle) * XY[:, :, 0] + np.sin(angle) * XY[:, :, 1]
        B = np.empty((speeds.size, 2 * H.shape[1]), dtype=complex)
        B[:, 0::2], B[:, 1::2] = H, 1j * H
        rpm = speeds / RPM
        if self.runup is not None:
            lo = self.runup["rpm_start"]
            # the gyroscopic matrix frozen at the first crossed mode: it matters there
            hi, w_first = transient_end_rpm(r, lo, self.runup["rpm_end"],
                                            self.runup["rate_rpm_s"], TRANSIENT_TOL)
            sel = (rpm >= lo) & (rpm <= hi)
            if sel.any() and hi > lo:
                rr, Z = _tracked_runup(r, lo, hi, self.runup["rate_rpm_s"],
                                       self.probe["position"], w_first)
                Zp = np.cos(angle) * Z[..., 0] + np.sin(angle) * Z[..., 1]  # (rev, disk, u)
                Zp = Zp.reshape(len(rr), -1)
                for col in range(B.shape[1]):
                    B[sel, col] = (np.interp(rpm[sel], rr, Zp[:, col].real)
                                   + 1j * np.interp(rpm[sel], rr, Zp[:, col].imag))
        return B


@lru_cache(maxsize=32)
def _tracked_runup(rotor, rpm_start, rpm_end, rate_rpm_s, probe, gyro_speed):
    """:func:`runup_order_response` of the order model's settings, remembered: a fit
    asks for the same bearings more than once (a quarter of the calls on the RK-4
    run-up: a step's value and its Jacobian's base point, a pair started from its
    lead); the arrays are read-only."""
    rpm, Z = runup_order_response(rotor, rpm_start, rpm_end, rate_rpm_s, probe, n_modes=8,
                                  samples_per_rev=64, gyro_speed=gyro_speed)
    rpm.setflags(write=False)
    Z.setflags(write=False)
    return rpm, Z


def solve_real_linear(B, z, w):
    """Weighted least squares with *real* coefficients of complex columns."""
    A = B * w[:, None]
    coef, *_ = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.r_[(z * w).real, (z * w).imag],
                               rcond=None)
    return coef, B @ coef


def complex_pairs(coef):
    """Real coefficients of (U = 1, U = i) column pairs -> complex values."""
    return coef[0::2] + 1j * coef[1::2]


class Candidate:
    """Which of the order model's effects are switched on: a slow-roll runout vector,
    support anisotropy (stiffness and damping along principal axes)."""

    def __init__(self, runout, anisotropic):
        self.runout, self.anisotropic = runout, anisotropic

    @property
    def names(self) -> tuple:
        return (("anisotropy",) if self.anisotropic else ()) + (("runout",) if self.runout
                                                                  else ())

    @property
    def label(self):
        names = list(self.names)
        return names[0] if len(names) == 1 else (names or ["nominal"])


def predict(model, cand, p, speeds_fit, z_fit, se_fit, speeds_eval):
    """Fit the unbalances (and runout) in closed form on ``speeds_fit`` for bearing
    parameters ``p`` (log10); returns the coefficients, the 1x at ``speeds_eval`` (m)
    and the bearing values ``(kx, ky, cx, cy, angle)``."""
    if cand.anisotropic:
        # stiffness and damping each along the support's principal axes: a single
        # damping would tie the two modes of the split pair to one decay rate
        kx, ky, angle, cx, cy = 10 ** p[0], 10 ** p[1], p[2], 10 ** p[3], 10 ** p[4]
    else:
        kx = ky = 10 ** p[0]
        angle, cx = 0.0, 10 ** p[1]
        cy = cx
    allsp = np.unique(np.r_[speeds_fit, speeds_eval])
    B = model.basis(allsp, kx, ky, cx, cy, angle)
    evaluated()
    Bf = B[np.searchsorted(allsp, speeds_fit)]
    Be = B[np.searchsorted(allsp, speeds_eval)]
    if cand.runout:
        Bf = np.column_stack([Bf, np.ones(len(speeds_fit)), 1j * np.ones(len(speeds_fit))])
        Be = np.column_stack([Be, np.ones(len(speeds_eval)), 1j * np.ones(len(speeds_eval))])
    w = 1.0 / np.sqrt(se_fit**2 + (model.rtol * np.abs(z_fit)) ** 2)
    coef, _ = solve_real_linear(Bf, z_fit, w)
    return coef, Be @ coef, (kx, ky, cx, cy, angle)


def z2_of(z, s, se, rtol):
    """Squared residual over its variance (chi-square, 2 degrees of freedom), the model
    trusted to ``rtol`` of its size."""
    return np.abs(z - s) ** 2 / (se**2 + (rtol * np.abs(s)) ** 2)


def fit_bearings(model, cand, bins, train, bounds, start=None):
    """Least-squares bearing parameters (log10) of a candidate on the training bins, and
    their standard errors; from ``start`` (the calibrated isotropic rotor's log10 k, c)
    or from a spread of starts over ``bounds``."""
    z, se, sp = bins.z.to_numpy()[train], bins.se.to_numpy()[train], bins.speed.to_numpy()[train]

    def resid(p):
        _, s, _ = predict(model, cand, p, sp, z, se, sp)
        d = (z - s) / np.sqrt(se**2 + (model.rtol * np.abs(s)) ** 2)
        return np.r_[d.real, d.imag]

    (klo, khi), (clo, chi) = bounds
    if cand.anisotropic:
        lo = [np.log10(klo), np.log10(klo), 0.0, np.log10(clo), np.log10(clo)]
        hi = [np.log10(khi), np.log10(khi), np.pi / 2, np.log10(chi), np.log10(chi)]
    else:
        lo, hi = [np.log10(klo), np.log10(clo)], [np.log10(khi), np.log10(chi)]
    starts = []
    if start is not None:  # from the calibrated isotropic rotor
        k0, c0 = start
        if cand.anisotropic:
            # a coarse scan of the split and the probe angle, then local search from the
            # two best: the cost has one basin per pairing of peaks and axes
            grid = []
            for d in (0.05, 0.1, 0.15, 0.25):
                for sh in (-d, 0.0, d):
                    for ang in np.radians([15, 30, 45, 60, 75]):
                        x = np.clip([k0 + sh - d, k0 + sh + d, ang, c0, c0], lo, hi)
                        grid.append((float(np.sum(resid(x) ** 2)), x))
            grid.sort(key=lambda g: g[0])
            starts = [g[1] for g in grid[:2]]
        else:
            starts.append([k0, c0])
    else:
        for ks in (0.25, 0.5, 0.75):
            starts.append([lo[0] + ks * (hi[0] - lo[0]), lo[-1] + 0.5 * (hi[-1] - lo[-1])])
    best = None
    for x0 in starts:
        res = least_squares(resid, np.clip(x0, lo, hi), bounds=(lo, hi), x_scale=1.0,
                            diff_step=1e-4, max_nfev=60)
        if best is None or res.cost < best.cost:
            best = res
    J = best.jac
    s2 = 2 * best.cost / max(J.shape[0] - J.shape[1], 1)
    sd_log = np.sqrt(np.clip(np.diag(np.linalg.pinv(J.T @ J) * s2), 0, None))
    return best.x, sd_log
