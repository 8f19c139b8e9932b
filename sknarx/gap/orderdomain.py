"""Gap diagnosis on order-domain measurements (Bode data: speed, 1x amplitude and phase).

Most rotating-machinery users have order-tracked run-ups or coast-downs, not raw
time series. This module takes such a table, bins it, and diagnoses it against a
linear rotor described by a file (:mod:`sknarx.rotor.beam`), whose steady order
response is exact and cheap.

Model of the measured 1x vector at speed ``w``:
``X(w) = U1 H1(w; p) + U2 H2(w; p) [+ R]`` with ``H_j`` the response at the probe
to a unit unbalance at disk j, ``U_j`` the (unknown, complex) residual unbalances,
``R`` a slow-roll runout vector and ``p`` the bearing parameters. For given ``p``
the complex unknowns enter linearly and are solved in closed form (variable
projection); ``p`` is fitted by least squares from several starts.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from ..plotting import plt, save, to_data_uri
from ..rotor.beam import beam_rotor_from_config

__all__ = ["load_bode", "bin_bode", "diagnose_order_domain"]

RPM = 2 * np.pi / 60.0
RTOL = 0.02  # model-form tolerance of a lumped linear rotor
NOT_TESTABLE = {
    "misalignment": "AC-coupled probes give no shaft centreline, and a 1x-only record has no 2x",
    "crack": "needs 2x/3x orders, not in a 1x Bode record",
    "rub": "needs harmonics and sub-synchronous orders, not in a 1x Bode record",
    "looseness": "needs harmonics and sub-synchronous orders, not in a 1x Bode record",
    "clearance": "the rig has no rolling-element bearing model with clearance to change",
    "speed-fluctuation": "needs the raw signal (sidebands); order tracking removes it",
    "noise": "characterised from the scatter of the order vectors, not a verdict",
}


def load_bode(path, measurement: dict) -> pd.DataFrame:
    """One row per revolution: speed (rad/s) and the complex 1x vector (m, 0-peak).

    ``measurement`` names the columns and units (see ``examples/rk4/rotor.toml``).
    """
    df = pd.read_csv(path)
    sc = measurement.get("speed_column", "rpm")
    ac = measurement.get("amplitude_column", "amp_1x")
    pc = measurement.get("phase_column", "phase_1x_deg")
    missing = [c for c in (sc, ac, pc) if c not in df.columns]
    if missing:
        raise ValueError(f"The Bode file lacks column(s) {missing}; the rotor file's "
                         "[measurement] section names the speed, amplitude and phase columns.")
    d = df[[sc, ac, pc]].apply(pd.to_numeric, errors="coerce")
    if d.isna().any().any():
        raise ValueError("The Bode file has empty or non-numeric values; clean it first.")
    rpm = d[sc].to_numpy()
    amp = d[ac].to_numpy() * float(measurement.get("amplitude_scale", 1.0))
    ph = np.radians(d[pc].to_numpy())
    if np.any(rpm <= 0) or np.any(amp < 0):
        raise ValueError("Speeds must be positive and amplitudes non-negative.")
    return pd.DataFrame({"rpm": rpm, "speed": rpm * RPM, "z": amp * np.exp(1j * ph)})


def bin_bode(rows: pd.DataFrame, width_rpm=20.0, max_n=10) -> pd.DataFrame:
    """Vector-average revolutions in speed bins, with a standard error per bin.

    The per-revolution noise is estimated from second differences of successive
    revolutions (blind to a response that varies linearly with speed, as it does
    between revolutions even near a resonance), as a running median over 31
    revolutions; a bin's standard error uses at most ``max_n`` revolutions, so the
    dense 5000 rpm plateau does not outweigh the run-up.
    """
    rows = rows.sort_values("rpm").reset_index(drop=True)
    edges = np.arange(np.floor(rows.rpm.min()), rows.rpm.max() + width_rpm, width_rpm)
    idx = np.digitize(rows.rpm, edges)
    z = rows.z.to_numpy()
    d2 = np.abs(z[2:] - 2 * z[1:-1] + z[:-2]) / np.sqrt(6.0)
    d2 = np.r_[d2[0], d2, d2[-1]]
    # median of |complex Gaussian| is sigma*sqrt(2 ln 2) per component pair
    local = pd.Series(d2).rolling(31, center=True, min_periods=5).median()
    rows["noise"] = local.to_numpy() / np.sqrt(2 * np.log(2))
    out = []
    for _, g in rows.groupby(idx):
        n = len(g)
        sigma = float(np.median(g.noise))
        out.append({"rpm": float(g.rpm.mean()), "speed": float(g.speed.mean()),
                    "z": complex(g.z.mean()), "n": n,
                    "se": sigma / np.sqrt(min(n, max_n))})
    return pd.DataFrame(out)


class _Model:
    """Linear-in-unbalance order model of the rotor at the probe."""

    def __init__(self, rotor, probe):
        self.rotor = rotor
        self.probe = probe

    def basis(self, speeds, kx, ky, c, angle=0.0):
        """Probe response to unit unbalances; the probe reads the displacement along
        ``angle`` (rad) from the support's x principal axis."""
        r = self.rotor.with_bearings(kxx=kx, kyy=ky, cxx=c, cyy=c)
        XY = r.probe_responses(speeds, self.probe["position"])
        return np.cos(angle) * XY[:, :, 0] + np.sin(angle) * XY[:, :, 1]


def _solve_linear(B, z, w):
    """Weighted complex least squares; returns coefficients and the fitted vector."""
    A = B * w[:, None]
    coef, *_ = np.linalg.lstsq(A, z * w, rcond=None)
    return coef, B @ coef


class _Candidate:
    def __init__(self, runout, anisotropic):
        self.runout, self.anisotropic = runout, anisotropic

    @property
    def label(self):
        parts = (["anisotropy"] if self.anisotropic else []) + (["runout"] if self.runout else [])
        return parts[0] if len(parts) == 1 else (parts or ["nominal"])


def _predict(model, cand, p, speeds_fit, z_fit, se_fit, speeds_eval):
    if cand.anisotropic:
        kx, ky, angle, c = 10 ** p[0], 10 ** p[1], p[2], 10 ** p[3]
    else:
        kx = ky = 10 ** p[0]
        angle, c = 0.0, 10 ** p[1]
    allsp = np.unique(np.r_[speeds_fit, speeds_eval])
    B = model.basis(allsp, kx, ky, c, angle)
    Bf = B[np.searchsorted(allsp, speeds_fit)]
    Be = B[np.searchsorted(allsp, speeds_eval)]
    if cand.runout:
        Bf = np.column_stack([Bf, np.ones(len(speeds_fit))])
        Be = np.column_stack([Be, np.ones(len(speeds_eval))])
    w = 1.0 / np.sqrt(se_fit**2 + (RTOL * np.abs(z_fit)) ** 2)
    coef, _ = _solve_linear(Bf, z_fit, w)
    return coef, Be @ coef, (kx, ky, c, angle)


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
        lo = [np.log10(klo), np.log10(klo), 0.0, np.log10(clo)]
        hi = [np.log10(khi), np.log10(khi), np.pi / 2, np.log10(chi)]
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
                        x = np.clip([k0 + sh - d, k0 + sh + d, ang, c0], lo, hi)
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


def _blocks(n, size=3):
    """Alternating blocks of ``size`` bins: True for training, False for held-out."""
    return (np.arange(n) // size) % 2 == 0


def _regions(bins, z2, noisy_rpm, thr=9.0):
    excess = np.clip(z2 - 2.0, 0, None)
    total = excess.sum()
    out, start = [], None
    sig = z2 > thr
    for i in range(len(bins) + 1):
        if i < len(bins) and sig[i]:
            start = i if start is None else start
        elif start is not None:
            sl = slice(start, i)
            out.append({"speed_range": [float(bins.speed.iloc[start]),
                                        float(bins.speed.iloc[i - 1])],
                        "rpm_range": [float(bins.rpm.iloc[start]), float(bins.rpm.iloc[i - 1])],
                        "order": "1x", "channel": "plane1_x", "window": "run-up",
                        "share": float(excess[sl].sum() / total) if total else 0.0,
                        "noisy_region": bool(bins.rpm.iloc[start] > noisy_rpm)})
            start = None
    out.sort(key=lambda r: -r["share"])
    return out


def diagnose_order_domain(measured_path, cfg, out, command, quiet=False) -> dict:
    """Diagnose a 1x Bode record against the rotor of ``cfg``; writes the report files."""
    from .. import __version__

    rotor, info = beam_rotor_from_config(cfg)
    meas_cfg = info["measurement"]
    probe = info["probes"][0]
    rows = load_bode(measured_path, meas_cfg)
    bins = bin_bode(rows)
    n = len(bins)
    train = _blocks(n)
    held = ~train
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
    p_cal, sd_cal = _fit(model, nominal, bins, train, bounds)
    start = (p_cal[0], p_cal[1])
    coef_cal, s_cal, kcs_cal, z2_cal = evaluate(nominal, p_cal)
    E_before = float(np.clip(z2_cal[held] - 2, 0, None).sum())
    crit_cal = rotor.with_bearings(kxx=kcs_cal[0], kyy=kcs_cal[0]).natural_frequencies(2)

    ranking = []
    fits = {}
    for cand in (_Candidate(True, False), _Candidate(False, True),
                 _Candidate(True, True)):
        p, sd = _fit(model, cand, bins, train, bounds, start=start)
        coef, s_all, kcs, z2 = evaluate(cand, p)
        E = float(np.clip(z2[held] - 2, 0, None).sum())
        params = {"bearing_damping": kcs[2]}
        if cand.anisotropic:
            params.update(kx=kcs[0], ky=kcs[1], probe_angle_deg=float(np.degrees(kcs[3])))
            freqs = rotor.with_bearings(kxx=kcs[0], kyy=kcs[1], cxx=kcs[2],
                                        cyy=kcs[2]).natural_frequencies(2)
            params["critical_speeds_rpm"] = sorted((freqs / RPM).tolist())
        else:
            params["bearing_stiffness"] = kcs[0]
            params["critical_speed_rpm"] = float(
                rotor.with_bearings(kxx=kcs[0], kyy=kcs[0]).natural_frequencies(1)[0] / RPM)
        names = ["kx", "ky", "probe_angle", "c"] if cand.anisotropic else ["k", "c"]
        std = {k: float(v if k == "probe_angle" else v * np.log(10) * 10 ** p[i])
               for i, (k, v) in enumerate(zip(names, sd, strict=True))}
        if cand.runout:
            R = coef[-1]
            params.update(runout_amplitude_m=float(abs(R)), runout_phase_deg=float(
                np.degrees(np.angle(R))))
        ranking.append({
            "effect": cand.label, "params": params, "params_std": std,
            "heldout_gap_before": E_before, "heldout_gap_after": E,
            "shrink": 1 - E / E_before if E_before > 0 else 0.0,
            "score": E + 2.0 * (len(p) + (2 if cand.runout else 0) - 2),
            "evidence": _evidence(cand, bins, z, s_cal, s_all, params, rows),
            "unbalance_kg_m": [[float(abs(u)), float(np.degrees(np.angle(u)))] for u in
                               coef[: len(rotor.disks)]],
        })
        fits[json.dumps(cand.label)] = s_all
    for name, why in NOT_TESTABLE.items():
        ranking.append({"effect": name, "testable": False, "reason": why})
    tested = [r for r in ranking if r.get("testable", True)]
    tested.sort(key=lambda r: r["score"])
    untested = [r for r in ranking if not r.get("testable", True)]
    best = tested[0]
    singles = [r for r in tested if isinstance(r["effect"], str)]
    verdict = best["effect"] if best["shrink"] >= 0.5 else "unexplained"
    if isinstance(verdict, list) and singles and best["shrink"] < max(
            s["shrink"] for s in singles) + 0.15:
        top = max(singles, key=lambda r: r["shrink"])
        verdict = top["effect"] if top["shrink"] >= 0.5 else "unexplained"
        best = top
    s_best = fits[json.dumps(best["effect"])]
    rng = np.random.default_rng(0)
    hb = np.clip(z2_cal - 2, 0, None)
    ha = np.clip(_z2(z, s_best, se) - 2, 0, None)
    hidx = np.flatnonzero(held)
    boot = []
    for _ in range(300):
        pick = rng.choice(hidx, hidx.size, replace=True)
        boot.append(1 - ha[pick].sum() / max(hb[pick].sum(), 1e-300))
    noisy = float(meas_cfg.get("noisy_above_rpm", np.inf))
    where = _regions(bins, z2_cal, noisy)
    doc = {
        "verdict": verdict,
        "ranking": tested + untested,
        "where": where,
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
                               coef_cal],
        },
        "gap_before": {"heldout_excess": E_before,
                       "nominal_as_described_heldout_excess": float(
                           np.clip(z2_nom[held] - 2, 0, None).sum())},
        "split": {"bins": n, "train_bins": int(train.sum()), "heldout_bins": int(held.sum()),
                  "scheme": "alternating blocks of 3 bins of 20 rpm"},
        "limits": [
            "AC-coupled probes: no shaft centreline, so no static (misalignment) preload.",
            "Only the 1x order is in the file: harmonic and sub-synchronous signatures "
            "(crack, rub, looseness) cannot be tested.",
            f"Above ~{noisy:.0f} rpm the 1x is ~0.03 V with tens of degrees of phase "
            "scatter: those bins carry large standard errors and little weight.",
            "The run-up (~228 rpm/s) is treated as quasi-steady.",
        ],
        "sknarx_version": __version__, "command": command,
    }
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figs = _figures(out, bins, s_nom, s_cal, s_best, doc)
    (out / "diagnosis.json").write_text(json.dumps(doc, indent=1, default=float))
    (out / "report.html").write_text(_html(doc, figs))
    return doc


def _evidence(cand, bins, z, s_before, s_after, params, rows):
    ev = []
    if cand.runout:
        low = bins.rpm < 1250
        frac = float(np.mean(params["runout_amplitude_m"] / np.abs(z[low.to_numpy()])))
        ev.append(f"constant 1x vector {1e6 * params['runout_amplitude_m']:.1f} um at "
                  f"{params['runout_phase_deg']:.0f} deg: {100 * frac:.0f} % of the raw 1x "
                  "below 1250 rpm (source: 60-70 % at 1000-1200 rpm)")
    if cand.anisotropic:
        c1, c2 = params["critical_speeds_rpm"]
        ev.append(f"split critical speed: {c1:.0f} and {c2:.0f} rpm (measured peaks 1648 "
                  "and ~1770 rpm)")
    err_b = np.abs(z - s_before)
    err_a = np.abs(z - s_after)
    i = int(np.argmax(err_b - err_a))
    ev.append(f"largest gain at {bins.rpm.iloc[i]:.0f} rpm: |gap| {1e6 * err_b[i]:.1f} -> "
              f"{1e6 * err_a[i]:.1f} um")
    return ev


def _figures(out, bins, s_nom, s_cal, s_best, doc):
    rpm = bins.rpm.to_numpy()
    z = bins.z.to_numpy()
    lab = doc["verdict"] if isinstance(doc["verdict"], str) else " + ".join(doc["verdict"])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a1.semilogy(rpm, np.abs(z) * 1e6, "k.", ms=3, label="measured (binned)")
    for s, style, name in ((s_nom, "c:", "nominal as described"),
                           (s_cal, "b--", "nominal, calibrated bearings"),
                           (s_best, "r-", f"corrected: {lab}")):
        a1.semilogy(rpm, np.abs(s) * 1e6, style, lw=1, label=name)
        a2.plot(rpm, np.degrees(np.angle(s)), style, lw=1)
    a2.plot(rpm, np.degrees(np.angle(z)), "k.", ms=3)
    a1.set(ylabel="1x amplitude (um, 0-pk)", title="RK-4 run-up: Bode plot")
    a1.legend(fontsize=7)
    a2.set(xlabel="speed (rpm)", ylabel="phase (deg)")
    figs = {"bode": save(fig, out / "bode.png")}
    fig, ax = plt.subplots(figsize=(5, 5))
    sel = rpm < 2400
    ax.plot(z.real[sel] * 1e6, z.imag[sel] * 1e6, "k.", ms=3, label="measured")
    for s, style, name in ((s_cal, "b--", "nominal, calibrated"), (s_best, "r-", "corrected")):
        ax.plot(s.real[sel] * 1e6, s.imag[sel] * 1e6, style, lw=1, label=name)
    ax.set(xlabel="Re 1x (um)", ylabel="Im 1x (um)", title="Polar plot (< 2400 rpm)")
    ax.set_aspect("equal")
    ax.legend(fontsize=7)
    figs["polar"] = save(fig, out / "polar.png")
    return figs


def _html(doc, figs):
    v = doc["verdict"] if isinstance(doc["verdict"], str) else " + ".join(doc["verdict"])
    rows = "".join(
        f"<tr><td>{html.escape(str(r['effect']))}</td><td>{r['shrink']:.2f}</td>"
        f"<td>{html.escape(json.dumps(r['params'], default=float))}</td>"
        f"<td>{html.escape('; '.join(r['evidence']))}</td></tr>"
        for r in doc["ranking"] if r.get("testable", True))
    untested = "".join(f"<li>{html.escape(r['effect'])}: {html.escape(r['reason'])}</li>"
                       for r in doc["ranking"] if not r.get("testable", True))
    where = "".join(
        f"<tr><td>{r['rpm_range'][0]:.0f}-{r['rpm_range'][1]:.0f}</td><td>{r['order']}</td>"
        f"<td>{100 * r['share']:.1f} %</td><td>{'yes' if r['noisy_region'] else ''}</td></tr>"
        for r in doc["where"][:12])
    imgs = "".join(f'<figure><img src="{to_data_uri(p)}"></figure>' for p in figs.values())
    nc = doc["nominal_calibration"]
    css = ("body{font-family:system-ui,sans-serif;max-width:1000px;margin:2em auto}"
           "table{border-collapse:collapse;font-size:0.85em}td,th{border:1px solid #ccc;"
           "padding:3px 6px}img{max-width:100%}")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>sknarx gap: order
domain</title><style>{css}</style></head><body><h1>Sim-to-real gap: order-domain diagnosis</h1>
<p>sknarx {html.escape(doc['sknarx_version'])}; <code>{html.escape(doc['command'])}</code></p>
<h2>Verdict: {html.escape(v)} - {100 * doc['shrink']:.0f} % of the held-out gap removed
(5-95 %: {100 * doc['shrink_band'][0]:.0f}-{100 * doc['shrink_band'][1]:.0f} %)</h2>
<h2>Nominal calibration</h2><p>The described rotor's first critical speed is
{nc['first_critical_rpm']['nominal']:.0f} rpm against the measured
{nc['first_critical_rpm']['measured']} rpm: the bearing stiffness (uncertain) was calibrated
from {nc['bearing_stiffness_N_per_m']['nominal']:.3g} to
{nc['bearing_stiffness_N_per_m']['calibrated']:.3g} +- {nc['bearing_stiffness_N_per_m']['std']:.2g}
N/m and the damping from {nc['bearing_damping_N_s_per_m']['nominal']:.3g} to
{nc['bearing_damping_N_s_per_m']['calibrated']:.3g} +- {nc['bearing_damping_N_s_per_m']['std']:.2g}
N s/m (first critical now {nc['first_critical_rpm']['calibrated']:.0f} rpm).</p>
{imgs}
<h2>Where</h2><table><tr><th>rpm</th><th>order</th><th>share of gap</th><th>noisy region</th>
</tr>{where}</table>
<h2>Which</h2><table><tr><th>candidate</th><th>shrink</th><th>parameters</th><th>evidence</th>
</tr>{rows}</table><p>Not testable with these data:</p><ul>{untested}</ul>
<h2>Limits</h2><ul>{''.join(f'<li>{html.escape(x)}</li>' for x in doc['limits'])}</ul>
</body></html>"""
