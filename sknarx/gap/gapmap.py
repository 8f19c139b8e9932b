"""Where simulation and measurement disagree: the gap map over speed x order x channel.

Each measured feature is compared with its simulated twin, normalised by a noise
floor: ``z2 = |M - S|^2 / (se_M^2 + se_S^2 + (rtol |S|)^2)``, whose expectation is 2
for a complex order vector when the two agree within noise (chi-square with two
degrees of freedom) -- ``rtol`` (1 % by default) admits the model-form error no
calibration removes. The *excess* ``max(z2 - 2, 0)`` is the gap that noise cannot
explain; regions are runs of adjacent speeds where it is significant, ranked by
their share of the total excess.

Small phase offsets of the once-per-revolution reference are removed first: per
speed step, the measured vectors are rotated by ``-k delta`` with ``delta`` the
1x phase difference (bounded by ``max_offset_deg``), so a jittery keyphasor does
not masquerade as a gap.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .features import is_nonsync

__all__ = ["compare", "regions", "gap_statistic", "true_runs"]


def true_runs(mask, max_hole: int = 0) -> list[tuple[int, int]]:
    """Half-open index ranges of the runs of True in ``mask``.

    Runs separated by at most ``max_hole`` False entries are joined; a run always
    starts and ends on a True entry.
    """
    idx = np.flatnonzero(np.asarray(mask, dtype=bool))
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > max_hole + 1)
    starts = np.r_[idx[0], idx[cut + 1]]
    stops = np.r_[idx[cut], idx[-1]] + 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))

_ORDER_K = {"1/3x": 1 / 3, "1/2x": 1 / 2, "1x": 1.0, "2x": 2.0, "3x": 3.0}
NONSYNC_SIGMAS = 3.0


def _align(meas: pd.DataFrame, sim: pd.DataFrame, max_offset_deg: float) -> pd.DataFrame:
    key = ["speed", "window", "channel", "feature"]
    m = meas.set_index(key)
    s = sim.set_index(key).reindex(m.index)
    Mc = m["re"].to_numpy() + 1j * m["im"].to_numpy()
    Sc = s["re"].to_numpy() + 1j * s["im"].to_numpy()
    speeds = m.index.get_level_values("speed").to_numpy()
    feats = m.index.get_level_values("feature").to_numpy()
    out = Mc.copy()
    lim = np.radians(max_offset_deg)
    is1 = feats == "1x"
    for w in np.unique(speeds):
        sel = speeds == w
        d = np.angle(np.sum(Mc[sel & is1] * np.conj(Sc[sel & is1])))
        d = float(np.clip(d, -lim, lim))
        for f, k in _ORDER_K.items():
            idx = sel & (feats == f)
            out[idx] = Mc[idx] * np.exp(-1j * k * d)
    return out, Sc, m, s


#: the nominal model's own harmonics and lines (from the bearings' contact law, whose
#: clearance, exponent and housing are uncertain) are trusted to within this share of
#: their size: an effect must add more than the model's own harmonic to be seen
HARMONIC_TOL = 1.0


def model_form_var(meas: pd.DataFrame) -> np.ndarray:
    """Variance (m^2) of a measured feature's ``model_tol`` column: the model-form
    tolerance, in metres, fixed once from the updated nominal model (0 or absent: none).

    Absolute, not a share of the simulation being compared: a tolerance that grew with
    the candidate's own harmonics would reward a candidate for inflating them."""
    if "model_tol" not in meas.columns:
        return np.zeros(len(meas))
    return meas["model_tol"].fillna(0.0).to_numpy(dtype=float) ** 2


def compare(meas: pd.DataFrame, sim: pd.DataFrame, rtol: float = 0.01,
            max_offset_deg: float = 5.0) -> pd.DataFrame:
    """Feature-by-feature gap between measured and simulated order features.

    A ``model_tol`` column in ``meas`` (m) widens each feature's tolerance by the
    model-form error the nominal model is allowed (see ``diagnosis``).
    """
    Mc, Sc, m, s = _align(meas, sim, max_offset_deg)
    feats = m.index.get_level_values("feature").to_numpy()
    se_m = m["se"].to_numpy()
    se_s = s["se"].to_numpy()
    nons = np.array([is_nonsync(f) for f in feats], dtype=bool)
    diff = np.abs(Mc - Sc)
    var = se_m**2 + se_s**2 + (rtol * np.abs(Sc)) ** 2
    var = np.where(nons, (NONSYNC_SIGMAS * se_m) ** 2 + (NONSYNC_SIGMAS * se_s) ** 2
                   + (rtol * np.abs(Sc)) ** 2, var) + model_form_var(m)
    var = np.maximum(var, 1e-300)
    z2 = diff**2 / var
    expect = np.where(nons, 1.0, 2.0)
    out = m.index.to_frame(index=False)
    out["measured"] = np.abs(Mc)
    out["simulated"] = np.abs(Sc)
    out["gap"] = diff
    out["z2"] = z2
    out["excess"] = np.clip(z2 - expect, 0.0, None)
    return out


def fast_residual(Mc, se_m, Sc, se_s, nons, speed_idx, order_k, rtol=0.01,
                  max_offset_deg=5.0, model_tol=None):
    """Normalised residuals of aligned feature arrays (the calibration's inner loop);
    ``model_tol`` (m) as in :func:`compare`, per feature."""
    lim = np.radians(max_offset_deg)
    is1 = order_k == 1.0
    num = np.bincount(speed_idx[is1], weights=(Mc[is1] * np.conj(Sc[is1])).real)
    den = np.bincount(speed_idx[is1], weights=(Mc[is1] * np.conj(Sc[is1])).imag)
    delta = np.clip(np.arctan2(den, num), -lim, lim)
    M = np.where(nons, Mc, Mc * np.exp(-1j * order_k * delta[speed_idx]))
    var = np.where(nons, (NONSYNC_SIGMAS * se_m) ** 2 + (NONSYNC_SIGMAS * se_s) ** 2,
                   se_m**2 + se_s**2) + (rtol * np.abs(Sc)) ** 2
    if model_tol is not None:
        var = var + model_tol**2
    d = (M - Sc) / np.sqrt(np.maximum(var, 1e-300))
    return np.concatenate([d.real, d.imag])


def gap_statistic(cmp: pd.DataFrame) -> float:
    """Total excess gap (dimensionless, 0 when the two agree within noise)."""
    return float(cmp["excess"].sum())


def regions(cmp: pd.DataFrame, z_threshold: float = 9.0) -> list[dict]:
    """Runs of adjacent speeds with a significant gap, ranked by share of the total excess."""
    total = cmp["excess"].sum()
    out = []
    if total <= 0:
        return out
    for (window, channel, feature), g in cmp.groupby(["window", "channel", "feature"]):
        g = g.sort_values("speed")
        speeds = g["speed"].to_numpy()
        excess = g["excess"].to_numpy()
        for a, b in true_runs(g["z2"].to_numpy() > z_threshold):
            out.append({
                "speed_range": [float(speeds[a]), float(speeds[b - 1])],
                "order": feature, "channel": channel, "window": window,
                "share": float(excess[a:b].sum() / total),
                "max_gap_m": float(g["gap"].to_numpy()[a:b].max()),
            })
    out.sort(key=lambda r: -r["share"])
    return out
