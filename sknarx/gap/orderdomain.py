"""Gap diagnosis on order-domain measurements (Bode data: speed, 1x amplitude and phase).

Most rotating-machinery users have order-tracked run-ups or coast-downs, not raw
time series. This module diagnoses such a table (loaded and binned by
:mod:`sknarx.gap.bode`) against a linear rotor described by a file
(:mod:`sknarx.rotor.beam`): its steady order response, or -- when the record is a
run-up too fast to be quasi-steady -- a simulated and order-tracked run-up
(:mod:`sknarx.rotor.runup`).

Model of the measured 1x vector at speed ``w``:
``X(w) = U1 H1(w; p) + U2 H2(w; p) [+ R]`` with ``H_j`` the response at the probe
to a unit unbalance at disk j, ``U_j`` the (unknown, complex) residual unbalances,
``R`` a slow-roll runout vector and ``p`` the bearing parameters. For given ``p``
the unknowns enter linearly (real-linearly in a run-up, where the acceleration
breaks the rotational symmetry) and are solved in closed form (variable
projection); ``p`` is fitted by least squares from several starts.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from .._progress import progress_bar
from .._report import provenance
from ..rotor.beam import beam_rotor_from_config
from ..rotor.runup import (
    damped_modes,
    runup_order_response,
    sweep_parameter,
    transient_end_rpm,
)
from .bode import RPM, bin_bode, load_bode, runup_rate
from .bode_report import figures, html_report
from .gapmap import true_runs

__all__ = ["load_bode", "bin_bode", "runup_rate", "diagnose_order_domain"]

logger = logging.getLogger(__name__)

RTOL = 0.02  # model-form tolerance of a lumped linear rotor
PAIR_MARGIN = 10.0  # held-out score (AIC) a pair must gain over its best member
SWEEP_LIMIT = 0.1  # sweep parameter above which a run-up is simulated, not taken as steady
# a crossed mode's free vibration below this share of its size counts as died out: half
# the model-form tolerance, so the switch to the steady response is not seen in a fit
TRANSIENT_TOL = RTOL / 2
# a bin's squared residual over its variance is chi-square with 2 degrees of freedom when
# the model is right; above 9 (p = exp(-9/2) ~ 0.011) the bin counts as disagreeing
SIGNIFICANT_Z2 = 9.0
NOT_TESTABLE = {
    "misalignment": "AC-coupled probes give no shaft centreline, and a 1x-only record has no 2x",
    "crack": "needs 2x/3x orders, not in a 1x Bode record",
    "rub": "needs harmonics and sub-synchronous orders, not in a 1x Bode record",
    "looseness": "needs harmonics and sub-synchronous orders, not in a 1x Bode record",
    "clearance": "the rig has no rolling-element bearing model with clearance to change",
    "speed-fluctuation": "needs the raw signal (sidebands); order tracking removes it",
    "noise": "characterised from the scatter of the order vectors, not a verdict",
}


class _Model:
    """Order model of the rotor at the probe, real-linear in the unbalances.

    ``basis`` returns, per speed bin, the probe's 1x response to a unit unbalance
    at each disk with its heavy spot at the keyphasor and 90 degrees ahead (two
    columns per disk). With ``runup`` (see :func:`runup_rate`) the bins come from an
    order-tracked simulation of the run-up at the measured rate up to the speed where
    the free vibration of every crossed mode of *this* rotor has decayed below
    ``TRANSIENT_TOL`` (:func:`~sknarx.rotor.runup.transient_end_rpm`); above it (and
    without ``runup``) from steady-state responses, which are then exact to that level.
    """

    def __init__(self, rotor, probe, runup=None):
        self.rotor = rotor
        self.probe = probe
        self.runup = runup

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
                rr, Z = runup_order_response(r, lo, hi, self.runup["rate_rpm_s"],
                                             self.probe["position"], n_modes=8,
                                             samples_per_rev=64, gyro_speed=w_first)
                Zp = np.cos(angle) * Z[..., 0] + np.sin(angle) * Z[..., 1]  # (rev, disk, u)
                Zp = Zp.reshape(len(rr), -1)
                for col in range(B.shape[1]):
                    B[sel, col] = (np.interp(rpm[sel], rr, Zp[:, col].real)
                                   + 1j * np.interp(rpm[sel], rr, Zp[:, col].imag))
        return B


def _solve_linear(B, z, w):
    """Weighted least squares with *real* coefficients of complex columns."""
    A = B * w[:, None]
    coef, *_ = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.r_[(z * w).real, (z * w).imag],
                               rcond=None)
    return coef, B @ coef


def _complex_pairs(coef):
    """Real coefficients of (U = 1, U = i) column pairs -> complex values."""
    return coef[0::2] + 1j * coef[1::2]


class _Candidate:
    def __init__(self, runout, anisotropic):
        self.runout, self.anisotropic = runout, anisotropic

    @property
    def label(self):
        parts = (["anisotropy"] if self.anisotropic else []) + (["runout"] if self.runout else [])
        return parts[0] if len(parts) == 1 else (parts or ["nominal"])


def _predict(model, cand, p, speeds_fit, z_fit, se_fit, speeds_eval):
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
    Bf = B[np.searchsorted(allsp, speeds_fit)]
    Be = B[np.searchsorted(allsp, speeds_eval)]
    if cand.runout:
        Bf = np.column_stack([Bf, np.ones(len(speeds_fit)), 1j * np.ones(len(speeds_fit))])
        Be = np.column_stack([Be, np.ones(len(speeds_eval)), 1j * np.ones(len(speeds_eval))])
    w = 1.0 / np.sqrt(se_fit**2 + (RTOL * np.abs(z_fit)) ** 2)
    coef, _ = _solve_linear(Bf, z_fit, w)
    return coef, Be @ coef, (kx, ky, cx, cy, angle)


def _z2(z, s, se):
    return np.abs(z - s) ** 2 / (se**2 + (RTOL * np.abs(s)) ** 2)


def _fit(model, cand, bins, train, bounds, start=None):
    z, se, sp = bins.z.to_numpy()[train], bins.se.to_numpy()[train], bins.speed.to_numpy()[train]

    def resid(p):
        _, s, _ = _predict(model, cand, p, sp, z, se, sp)
        d = (z - s) / np.sqrt(se**2 + (RTOL * np.abs(s)) ** 2)
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


def _locate(r, ranking_fits, s_cal, bins, z, se, held, noisy_rpm=np.inf, thr=SIGNIFICANT_Z2,
            max_hole=2):
    """Where each effect of a candidate acts: the speed range holding most of its gain.

    The gain of an effect is, per bin, the drop of ``z^2`` it brings -- over the
    calibrated nominal model for a single effect; for a member of a pair, over the
    pair with the runout vector removed (runout) or over the other member alone,
    refitted (anisotropy). Bins gaining more than ``thr`` are joined into runs (holes of
    up to ``max_hole`` bins bridged); the strongest run outside the noisy region is
    the location, and the four strongest runs are listed.
    """
    names = [r["effect"]] if isinstance(r["effect"], str) else list(r["effect"])
    s_full = ranking_fits[json.dumps(r["effect"])]
    rpm = bins.rpm.to_numpy()
    out = {}
    for name in names:
        rest = [n for n in names if n != name]
        if not rest:
            s_without = s_cal
        elif name == "runout":  # switched off inside the fit: the constant vector removed
            R = r["params"]["runout_amplitude_m"] * np.exp(
                1j * np.radians(r["params"]["runout_phase_deg"]))
            s_without = s_full - R
        else:  # the other member alone, refitted
            s_without = ranking_fits.get(json.dumps(rest[0]))
        if s_without is None:
            continue
        gain = _z2(z, s_without, se) - _z2(z, s_full, se)
        # a run does not straddle the noisy speed: its two sides are weighed apart
        runs = [piece for a, b in true_runs(gain > thr, max_hole=max_hole)
                for piece in _split_at(rpm, a, b, noisy_rpm)]
        if not runs:
            out[name] = {"rpm_range": None, "share_of_gain": 0.0}
            continue
        pos = np.clip(gain, 0, None)
        found = sorted(({"rpm_range": [float(rpm[a]), float(rpm[b - 1])],
                         "share_of_gain": float(pos[a:b].sum() / pos.sum()),
                         "noisy_region": bool(rpm[a] > noisy_rpm)} for a, b in runs),
                       key=lambda x: -x["share_of_gain"])
        # the main location: the strongest run outside the noisy region, if any
        clean = [f for f in found if not f["noisy_region"]] or found
        out[name] = {**clean[0], "runs": found[:4],
                     "heldout_gain": float(np.clip(gain[held], 0, None).sum())}
    return out


def _split_at(rpm, a, b, at):
    """The run of bins ``a:b`` cut where the speed first exceeds ``at``."""
    k = a + int(np.searchsorted(rpm[a:b], at, side="right"))
    return [(a, b)] if k in (a, b) else [(a, k), (k, b)]


def _local_minima(bins, lo_rpm, hi_rpm, curve=None):
    """Speeds of local minima of the binned 1x amplitude (or of a model ``curve`` at the
    bins) between two speeds."""
    rpm = bins.rpm.to_numpy()
    a = np.abs(bins.z.to_numpy() if curve is None else curve)
    i = np.flatnonzero((rpm > lo_rpm) & (rpm < hi_rpm))
    i = i[(i > 0) & (i < len(a) - 1)]
    return [float(rpm[k]) for k in i if a[k] < a[k - 1] and a[k] < a[k + 1]]


def _beat_comparison(bins, s_swept, s_quasi, f_n, expected, top_rpm):
    """How well a model reproduces the beat behind the peak: the amplitude minima of the
    measurement and of the swept model, and the complex residual above the peak (m, RMS
    over the bins between the measured peak and ``top_rpm``) of both models."""
    rpm = bins.rpm.to_numpy()
    z = bins.z.to_numpy()
    below = rpm < top_rpm
    peak = float(rpm[below][int(np.argmax(np.abs(z[below])))])
    above = (rpm > peak) & below
    hi = expected[-1] + 40

    def rms(s):
        return float(np.sqrt(np.mean(np.abs(z[above] - s[above]) ** 2)))

    out = {"measured_minima_rpm": _local_minima(bins, f_n, hi),
           "swept_model_minima_rpm": _local_minima(bins, f_n, hi, curve=s_swept),
           "expected_minima_rpm": list(expected),
           "above_peak_rpm": [peak, float(rpm[above].max()) if above.any() else peak],
           "complex_residual_rms_m": {"run-up model": rms(s_swept)}}
    if s_quasi is not None:
        out["complex_residual_rms_m"]["quasi-steady model"] = rms(s_quasi)
        out["quasi_over_swept"] = rms(s_quasi) / max(rms(s_swept), 1e-300)
    return out


def _gap_by_band(bins, z2_before, z2_after, held, noisy_rpm):
    """Held-out excess before/after, below and above the noisy speed."""
    rpm = bins.rpm.to_numpy()
    out = {}
    for name, sel in ((f"below {noisy_rpm:.0f} rpm", rpm <= noisy_rpm),
                      (f"above {noisy_rpm:.0f} rpm (noisy)", rpm > noisy_rpm)):
        m = sel & held
        b = float(np.clip(z2_before[m] - 2, 0, None).sum())
        a = float(np.clip(z2_after[m] - 2, 0, None).sum())
        out[name] = {"heldout_excess_before": b, "heldout_excess_after": a,
                     "shrink": 1 - a / b if b > 0 else 0.0, "bins": int(m.sum())}
    return out


def _blocks(n, size=3):
    """Alternating blocks of ``size`` bins: True for training, False for held-out."""
    return (np.arange(n) // size) % 2 == 0


def _regions(bins, z2, noisy_rpm, probe, thr=SIGNIFICANT_Z2):
    excess = np.clip(z2 - 2.0, 0, None)
    total = excess.sum()
    out = []
    for a, b in true_runs(z2 > thr):
        out.append({"speed_range": [float(bins.speed.iloc[a]), float(bins.speed.iloc[b - 1])],
                    "rpm_range": [float(bins.rpm.iloc[a]), float(bins.rpm.iloc[b - 1])],
                    "order": "1x", "channel": probe, "window": "run-up",
                    "share": float(excess[a:b].sum() / total) if total else 0.0,
                    "noisy_region": bool(bins.rpm.iloc[a] > noisy_rpm)})
    out.sort(key=lambda r: -r["share"])
    return out


def diagnose_order_domain(measured_path, cfg, out, command) -> dict:
    """Diagnose a 1x Bode record against the rotor of ``cfg``; writes the report files."""
    from .._version import __version__

    rotor, info = beam_rotor_from_config(cfg)
    meas_cfg = info["measurement"]
    probe = info["probes"][0]
    rows = load_bode(measured_path, meas_cfg)
    bins = bin_bode(rows)
    n = len(bins)
    train = _blocks(n)
    held = ~train
    mode = meas_cfg.get("response", "auto")
    if mode not in ("auto", "steady", "run-up"):
        raise ValueError(f"[measurement] response must be 'auto', 'steady' or 'run-up', got "
                         f"{mode!r}.")
    runup = runup_rate(rows) if mode != "steady" else None
    crit = meas_cfg.get("first_critical_rpm")
    model = _Model(rotor, probe)
    cal = info["calibration"]
    bounds = (tuple(cal.get("bearing_stiffness", (1e5, 1e8))),
              tuple(cal.get("bearing_damping", (1.0, 2000.0))))
    z, se, sp = bins.z.to_numpy(), bins.se.to_numpy(), bins.speed.to_numpy()
    b0 = rotor.bearings[0]

    def evaluate(cand, p):
        coef, s_all, kcs = _predict(model, cand, p, sp[train], z[train], se[train], sp)
        z2 = _z2(z, s_all, se)
        return coef, s_all, kcs, z2

    # the nominal model exactly as described (only the unbalance fitted)
    nominal = _Candidate(False, False)
    p_nom = np.log10([b0.kxx, b0.cxx])
    _, s_nom, _, z2_nom = evaluate(nominal, p_nom)
    # calibrating the uncertain nominal values (isotropic bearing stiffness, damping)
    logger.info("%d revolutions in %d speed bins; calibrating the nominal rotor (steady "
                "response)", len(rows), n)
    p_cal, sd_cal = _fit(model, nominal, bins, train, bounds)
    sweep_note, base_choice = None, None
    if runup is not None:
        # a fast run-up is not a sequence of steady states: simulate it when the
        # calibrated rotor says the sweep is not slow (the quasi-steady model is still
        # calibrated, for the report's comparison)
        k0, c0 = 10 ** p_cal[0], 10 ** p_cal[1]
        runup["sweep"] = sweep_parameter(rotor.with_bearings(kxx=k0, kyy=k0, cxx=c0, cyy=c0),
                                         runup["rate_rpm_s"])
        if mode == "run-up" or runup["sweep"]["sweep_parameter"] >= SWEEP_LIMIT:
            steady_model, p_steady = model, (p_cal, sd_cal)
            E_steady = float(np.clip(evaluate(nominal, p_cal)[3][held] - 2, 0, None).sum())
            model = _Model(rotor, probe, runup)
            logger.info("run-up at %.0f rpm/s is not quasi-steady (sweep parameter %.2f): "
                        "calibrating the simulated, order-tracked run-up", runup["rate_rpm_s"],
                        runup["sweep"]["sweep_parameter"])
            p_cal, sd_cal = _fit(model, nominal, bins, train, bounds)
            E_runup = float(np.clip(evaluate(nominal, p_cal)[3][held] - 2, 0, None).sum())
            base_choice = {"run-up model": E_runup, "quasi-steady model": E_steady}
        else:
            sweep_note, runup = runup, None
    start = (p_cal[0], p_cal[1])
    coef_cal, s_cal, kcs_cal, z2_cal = evaluate(nominal, p_cal)
    E_before = float(np.clip(z2_cal[held] - 2, 0, None).sum())
    crit_cal = rotor.with_bearings(kxx=kcs_cal[0], kyy=kcs_cal[0]).natural_frequencies(2)
    # below ~3/4 of the first critical the response is small and a runout stands out
    slow_rpm = 0.75 * float(crit if crit else crit_cal[0] / RPM)

    ranking = []
    fits = {}
    cands = (_Candidate(True, False), _Candidate(False, True), _Candidate(True, True))
    logger.info("fitting %d effect models to %d speed bins", len(cands), n)
    for cand in progress_bar(cands, desc="effect models", unit="fit"):
        p, sd = _fit(model, cand, bins, train, bounds, start=start)
        coef, s_all, kcs, z2 = evaluate(cand, p)
        E = float(np.clip(z2[held] - 2, 0, None).sum())
        if cand.anisotropic:
            params = {"kx": kcs[0], "ky": kcs[1], "cx": kcs[2], "cy": kcs[3],
                      "probe_angle_deg": float(np.degrees(kcs[4]))}
            freqs = rotor.with_bearings(kxx=kcs[0], kyy=kcs[1], cxx=kcs[2],
                                        cyy=kcs[3]).natural_frequencies(2)
            params["critical_speeds_rpm"] = sorted((freqs / RPM).tolist())
        else:
            params = {"bearing_stiffness": kcs[0], "bearing_damping": kcs[2]}
            params["critical_speed_rpm"] = float(
                rotor.with_bearings(kxx=kcs[0], kyy=kcs[0]).natural_frequencies(1)[0] / RPM)
        names = ["kx", "ky", "probe_angle", "cx", "cy"] if cand.anisotropic else ["k", "c"]
        std = {k: float(v if k == "probe_angle" else v * np.log(10) * 10 ** p[i])
               for i, (k, v) in enumerate(zip(names, sd, strict=True))}
        if cand.runout:
            R = _complex_pairs(coef)[-1]
            params.update(runout_amplitude_m=float(abs(R)), runout_phase_deg=float(
                np.degrees(np.angle(R))))
        ranking.append({
            "effect": cand.label, "params": params, "params_std": std,
            "heldout_gap_before": E_before, "heldout_gap_after": E,
            "shrink": 1 - E / E_before if E_before > 0 else 0.0,
            "score": E + 2.0 * (len(p) + (2 if cand.runout else 0) - 2),
            "evidence": _evidence(cand, bins, z, s_cal, s_all, params, rows, slow_rpm),
            "unbalance_kg_m": [[float(abs(u)), float(np.degrees(np.angle(u)))] for u in
                               _complex_pairs(coef)[: len(rotor.disks)]],
        })
        fits[json.dumps(cand.label)] = s_all
    for name, why in NOT_TESTABLE.items():
        ranking.append({"effect": name, "testable": False, "reason": why})
    tested = [r for r in ranking if r.get("testable", True)]
    tested.sort(key=lambda r: r["score"])
    untested = [r for r in ranking if not r.get("testable", True)]
    best = tested[0]
    singles = [r for r in tested if isinstance(r["effect"], str)]
    if isinstance(best["effect"], list) and singles:
        # a pair must beat its best member by more than chance on the held-out bins:
        # the score is an AIC (2 per parameter), and a margin of 10 is strong evidence
        top = min(singles, key=lambda r: r["score"])
        if top["score"] - best["score"] < PAIR_MARGIN:
            best = top
    verdict = best["effect"] if best["shrink"] >= 0.5 else "unexplained"
    noisy = float(meas_cfg.get("noisy_above_rpm", np.inf))
    for r in tested:
        r["located"] = _locate(r, ranking_fits=fits, s_cal=s_cal, bins=bins, z=z, se=se,
                               held=held, noisy_rpm=noisy)
    s_best = fits[json.dumps(best["effect"])]
    rng = np.random.default_rng(0)
    hb = np.clip(z2_cal - 2, 0, None)
    ha = np.clip(_z2(z, s_best, se) - 2, 0, None)
    hidx = np.flatnonzero(held)
    boot = []
    for _ in range(300):
        pick = rng.choice(hidx, hidx.size, replace=True)
        boot.append(1 - ha[pick].sum() / max(hb[pick].sum(), 1e-300))
    where = _regions(bins, z2_cal, noisy, probe.get("name", "probe"))
    z2_best = _z2(z, s_best, se)
    lab = best["effect"] if isinstance(best["effect"], str) else " + ".join(best["effect"])
    response = {"kind": "steady-state order response"}
    if sweep_note is not None:
        response.update(sweep=sweep_note["sweep"], rate_rpm_s=sweep_note["rate_rpm_s"],
                        why="the run-up is slow enough to be quasi-steady (sweep parameter "
                        f"{sweep_note['sweep']['sweep_parameter']:.3f} < {SWEEP_LIMIT})")
    s_quasi = None
    until = None
    if runup is not None:
        until, _ = transient_end_rpm(_rotor_of(rotor, best["params"]), runup["rpm_start"],
                                     runup["rpm_end"], runup["rate_rpm_s"], TRANSIENT_TOL)
        # the same verdict on a quasi-steady model: how much the sweep itself matters
        cand_best = next(c for c in cands if c.label == best["effect"])
        logger.info("the verdict on a quasi-steady model, for comparison")
        # started from the quasi-steady calibration, not the run-up one
        p_q, _ = _fit(steady_model, cand_best, bins, train, bounds,
                      start=(p_steady[0][0], p_steady[0][1]))
        _, s_quasi, _ = _predict(steady_model, cand_best, p_q, sp[train], z[train], se[train],
                                 sp)
        E_q = float(np.clip(_z2(z, s_quasi, se)[held] - 2, 0, None).sum())
        f_n = float(crit_cal[0] / RPM)
        alpha = runup["rate_rpm_s"] * RPM
        beat = [f_n + np.sqrt((2 * m + 1) * 2 * np.pi * alpha) / RPM for m in range(4)]
        response = {
            "kind": "order-tracked run-up simulation",
            "why": "set by the rotor file" if mode == "run-up" else
                   "the record is a ramp; with the rotor calibrated as quasi-steady, the "
                   "sweep parameter alpha/(zeta^2 w_n^2) at the first mode is "
                   f"{runup['sweep']['sweep_parameter']:.2f} (>= {SWEEP_LIMIT}: not slow)",
            "transient_tolerance": TRANSIENT_TOL,
            "sweep": runup["sweep"],
            "rate_rpm_s": runup["rate_rpm_s"],
            "simulated_rpm": [runup["rpm_start"], until],
            "steady_above_rpm": until,
            "verdict_heldout_excess": {"run-up model": best["heldout_gap_after"],
                                       "quasi-steady model": E_q},
            "beat_minima_expected_rpm": beat,
            "measured_minima_rpm": _local_minima(bins, f_n, beat[-1] + 40),
            "beat": _beat_comparison(bins, s_best, s_quasi, f_n, beat, min(noisy, until)),
        }
    if base_choice is not None:
        # both calibrated, no effect added: what the sweep alone is worth on held-out bins
        response["nominal_heldout_excess"] = base_choice
    doc = {
        "verdict": verdict,
        "ranking": tested + untested,
        "where": where,
        # where the corrected model still disagrees with the measurement, the same way
        "remaining": _regions(bins, z2_best, noisy, probe.get("name", "probe")),
        "significant_z2": SIGNIFICANT_Z2,
        "shrink": float(best["shrink"]) if verdict != "unexplained" else 0.0,
        "shrink_band": [float(np.percentile(boot, 5)), float(np.percentile(boot, 95))],
        "nominal_calibration": {
            "bearing_stiffness_N_per_m": {"nominal": b0.kxx, "calibrated": kcs_cal[0],
                                          "std": float(sd_cal[0] * np.log(10) * kcs_cal[0])},
            "bearing_damping_N_s_per_m": {"nominal": b0.cxx, "calibrated": kcs_cal[2],
                                          "std": float(sd_cal[-1] * np.log(10) * kcs_cal[2])},
            "first_critical_rpm": {"nominal": float(rotor.natural_frequencies(1)[0] / RPM),
                                   "calibrated": float(crit_cal[0] / RPM),
                                   "measured": meas_cfg.get("first_critical_rpm")},
            "unbalance_kg_m": [[float(abs(u)), float(np.degrees(np.angle(u)))] for u in
                               _complex_pairs(coef_cal)],
        },
        "located": best.get("located", {}),
        "gap_by_band": _gap_by_band(bins, z2_cal, z2_best, held, noisy),
        "response_model": response,
        "gap_before": {"heldout_excess": E_before,
                       "nominal_as_described_heldout_excess": float(
                           np.clip(z2_nom[held] - 2, 0, None).sum())},
        "split": {"bins": n, "train_bins": int(train.sum()), "heldout_bins": int(held.sum()),
                  "scheme": "alternating blocks of 3 bins of 20 rpm"},
        "limits": _limits(cfg, info, bins, noisy, runup, until),
        "sknarx_version": __version__, "command": command,
        "provenance": provenance(command),
    }
    modes = _verdict_modes(rotor, best)
    doc["critical_speeds_rpm"] = sorted(m["rpm"] for m in modes)
    doc["modes"] = modes
    sweep_info = (runup or sweep_note or {})
    if sweep_info:  # each mode of the verdict's rotor has its own decay time to compare
        alpha = sweep_info["rate_rpm_s"] * RPM
        for m in modes:
            m["sweep_parameter"] = float(alpha / (m["damping_ratio"] * m["rpm"] * RPM) ** 2)
    doc["sweep"] = {
        "rate_rpm_s": sweep_info.get("rate_rpm_s"),
        "sweep_parameter": sweep_info.get("sweep", {}).get("sweep_parameter"),
        "limit": SWEEP_LIMIT,
        "quasi_steady_valid": (None if not sweep_info else
                               bool(sweep_info["sweep"]["sweep_parameter"] < SWEEP_LIMIT)),
        "measure": "alpha / (zeta^2 w_n^2) at the first mode of the calibrated rotor",
    }
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _bode_fit_table(rows, bins, s_nom, s_cal, s_best, meas_cfg).to_csv(
        out / "bode_fit.csv", index=False)
    figs = figures(out, bins, s_nom, s_cal, s_best, doc, s_quasi,
                   z2={"calibrated nominal": z2_cal, f"corrected ({lab})": z2_best})
    (out / "diagnosis.json").write_text(json.dumps(doc, indent=1, default=float))
    (out / "report.html").write_text(html_report(doc, figs))
    return doc


def _rotor_of(rotor, params):
    """The rotor with the bearings of a candidate's fitted parameters."""
    if "kx" in params:
        return rotor.with_bearings(kxx=params["kx"], kyy=params["ky"], cxx=params["cx"],
                                   cyy=params["cy"])
    k, c = params["bearing_stiffness"], params["bearing_damping"]
    return rotor.with_bearings(kxx=k, kyy=k, cxx=c, cyy=c)


def _verdict_modes(rotor, best, n_draws=200):
    """Damped modes of the verdict's calibrated rotor, at rest, with standard errors from
    the fit's parameter errors (Monte Carlo on log-normal stiffness and damping)."""
    p, sd = best["params"], best.get("params_std", {})
    if "kx" in p:
        names = ("kx", "ky", "cx", "cy")
        v = np.array([p[k] for k in names])
        v_sd = np.array([sd.get(k, 0.0) for k in names])
    else:  # isotropic: one stiffness and one damping, drawn once for both axes
        v = np.array([p["bearing_stiffness"], p["bearing_damping"]])
        v_sd = np.array([sd.get("k", 0.0), sd.get("c", 0.0)])

    def modes(q):
        kx, ky, cx, cy = q if q.size == 4 else (q[0], q[0], q[1], q[1])
        return damped_modes(rotor.with_bearings(kxx=kx, kyy=ky, cxx=cx, cyy=cy), 2)

    w0, z0 = modes(v)
    rng = np.random.default_rng(0)
    draws = [np.concatenate(modes(v * np.exp(rng.standard_normal(v.size) * v_sd / v)))
             for _ in range(n_draws)]
    draws = np.array(draws)
    out = []
    for i in range(len(w0)):
        out.append({"rpm": float(w0[i] / RPM), "rpm_std": float(np.std(draws[:, i]) / RPM),
                    "damping_ratio": float(z0[i]),
                    "damping_ratio_std": float(np.std(draws[:, len(w0) + i]))})
    return sorted(out, key=lambda m: m["rpm"])


def _bode_fit_table(rows, bins, s_nom, s_cal, s_best, meas_cfg):
    """Measured and modelled 1x per revolution, in the input's units and phase convention
    (the models, computed per speed bin, are interpolated to each revolution's speed)."""
    scale = float(meas_cfg.get("amplitude_scale", 1.0))
    rpm = rows.rpm.to_numpy()
    b = bins.rpm.to_numpy()  # beyond the end bins' centres the end values hold
    out = {"rpm": rpm, "measured_amp": np.abs(rows.z.to_numpy()) / scale,
           "measured_phase_deg": np.degrees(np.angle(rows.z.to_numpy()))}
    for name, s in (("nominal", s_nom), ("corrected", s_best)):
        zi = np.interp(rpm, b, s.real) + 1j * np.interp(rpm, b, s.imag)
        out[f"{name}_amp"] = np.abs(zi) / scale
        out[f"{name}_phase_deg"] = np.degrees(np.angle(zi))
    return pd.DataFrame(out)[["rpm", "measured_amp", "measured_phase_deg", "nominal_amp",
                              "nominal_phase_deg", "corrected_amp", "corrected_phase_deg"]]


def _limits(cfg, info, bins, noisy, runup, until) -> list:
    """What these data cannot tell: computed from the record and the rotor file, plus the
    rig's own statements from its ``[report] limits``."""
    out = list(cfg.get("report", {}).get("limits", []))
    out.append("Only the 1x order is in the file: harmonic and sub-synchronous signatures "
               "(crack, rub, looseness) cannot be tested.")
    hi = bins.rpm.to_numpy() > noisy
    if np.isfinite(noisy) and hi.any():
        rel = float(np.median(bins.se.to_numpy()[hi] / np.abs(bins.z.to_numpy()[hi])))
        out.append(f"Above {noisy:.0f} rpm (the rotor file's noisy_above_rpm) the median "
                   f"standard error of a bin is {100 * rel:.0f} % of its 1x amplitude: those "
                   "bins carry little weight.")
    if runup is not None:
        out.append(f"The run-up ({runup['rate_rpm_s']:.0f} rpm/s) is simulated and "
                   "order-tracked like the measurement; the gyroscopic matrix is frozen at "
                   f"the first crossed mode, and above {until:.0f} rpm (where the crossed "
                   f"modes' free vibration has decayed below {100 * TRANSIENT_TOL:.0f} %) "
                   "the steady response is used.")
    else:
        out.append("The record is treated as quasi-steady.")
    # a Bode record carries one probe's 1x, whatever the rotor file describes
    out.append("One probe: the support anisotropy's principal axes and the probe angle "
               "are confounded with the split; both bearings are assumed alike.")
    return out


def _evidence(cand, bins, z, s_before, s_after, params, rows, slow_rpm):
    ev = []
    if cand.runout:
        low = bins.rpm < slow_rpm
        frac = float(np.mean(params["runout_amplitude_m"] / np.abs(z[low.to_numpy()])))
        ev.append(f"constant 1x vector {1e6 * params['runout_amplitude_m']:.1f} um at "
                  f"{params['runout_phase_deg']:.0f} deg: {100 * frac:.0f} % of the raw 1x "
                  f"below {slow_rpm:.0f} rpm (3/4 of the first critical)")
    if cand.anisotropic:
        c1, c2 = params["critical_speeds_rpm"]
        ev.append(f"split critical speed: {c1:.0f} and {c2:.0f} rpm (undamped, at rest)")
    err_b = np.abs(z - s_before)
    err_a = np.abs(z - s_after)
    i = int(np.argmax(err_b - err_a))
    ev.append(f"largest gain at {bins.rpm.iloc[i]:.0f} rpm: |gap| {1e6 * err_b[i]:.1f} -> "
              f"{1e6 * err_a[i]:.1f} um")
    return ev
