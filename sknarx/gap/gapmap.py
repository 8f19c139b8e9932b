"""Where simulation and measurement disagree: the gap map over speed x order x channel.

Each measured feature is compared with its simulated twin, normalised by a noise
floor: ``z2 = |M - S|^2 / (se_M^2 + se_S^2 + (rtol |S|)^2)``, whose expectation is 2
for a complex order vector when the two agree within noise (chi-square with two
degrees of freedom). The tolerances are the verdict rule's
(:class:`~sknarx.gap.VerdictRule`): ``rtol`` admits the model-form error no
calibration removes, a measured ``model_tol`` column the nominal model's stated
model-form error, a harmonic (1/3x-3x) also agrees to ``harmonic_rtol`` of the smaller
of its two sizes, and a non-synchronous line energy to ``line_sigmas`` of its standard
errors. The *excess* ``max(z2 - 2, 0)`` is the gap that noise cannot explain; regions
are runs of adjacent speeds where it is significant, ranked by their share of the
total excess.

Small phase offsets of the once-per-revolution reference are removed first: per speed
step, the measured vectors are rotated by ``-k delta`` with ``delta`` the 1x phase
difference (bounded by the rule's ``keyphasor_deg``), so a jittery keyphasor does not
masquerade as a gap; then each channel's 2x and 3x follow that channel's own 1x phase
error as far as its 1x tolerance admits (see ``_normalised``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..orders import ORDER_LABELS

__all__ = ["compare", "regions", "gap_statistic", "true_runs", "probe_offsets",
           "comparison_layout", "excess_of_residual", "fast_residual", "tolerances",
           "HARMONIC_TOL"]


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

#: each synchronous feature's shaft order (the non-synchronous lines: 0)
ORDER_K = {label: k for k, label in ORDER_LABELS.items()}

#: the nominal model's own harmonics and lines (from the bearings' contact law, whose
#: clearance, exponent and housing are uncertain) are trusted to their own size, not
#: beyond: an effect must add more than the model's own harmonic to be seen. A
#: definition (the model's harmonic is the unit), not a tuned share
HARMONIC_TOL = 1.0


def _rule(rule):
    """The verdict rule whose tolerances a comparison applies (the default's: None)."""
    if rule is None:
        from .rule import VerdictRule

        return VerdictRule()
    return rule


def tolerances(rule) -> dict:
    """The comparison's tolerances from a :class:`~sknarx.gap.VerdictRule` (the
    default's: None), as :func:`fast_residual` takes them."""
    rule = _rule(rule)
    return {"rtol": rule.rtol, "keyphasor_deg": rule.keyphasor_deg,
            "harmonic_rtol": rule.harmonic_rtol, "line_sigmas": rule.line_sigmas}


def model_tol(meas: pd.DataFrame) -> np.ndarray:
    """Each measured feature's model-form tolerance (m): its ``model_tol`` column, fixed
    once from the updated nominal model (0 or absent: none).

    Absolute, not a share of the simulation being compared: a tolerance that grew with
    the candidate's own harmonics would reward a candidate for inflating them."""
    if "model_tol" not in meas.columns:
        return np.zeros(len(meas))
    return meas["model_tol"].fillna(0.0).to_numpy(dtype=float)


def _per_group(idx, values, n):
    return np.bincount(idx, weights=values.real, minlength=n) + 1j * np.bincount(
        idx, weights=values.imag, minlength=n)


def whirl_tol(meas: pd.DataFrame) -> np.ndarray | None:
    """Each measured 1x's backward-whirl tolerance (m): its ``whirl_tol`` column, fixed
    once from the updated nominal model and the same on both channels of a probe pair;
    None when absent (the comparison stays channel by channel)."""
    if "whirl_tol" not in meas.columns:
        return None
    return meas["whirl_tol"].fillna(0.0).to_numpy(dtype=float)


def whirl_pairs(index: pd.MultiIndex) -> tuple[np.ndarray, np.ndarray]:
    """``(ix, iy)``: the positions of each probe pair's 1x (``xA`` with ``yA``, at one
    speed step and window) in features indexed by ``speed, window, channel, feature``."""
    frame = index.to_frame(index=False)
    ch = frame["channel"].astype(str)
    is_x = (frame["feature"] == "1x") & ch.str.startswith("x")
    pos = pd.Series(np.arange(len(frame)), index=pd.MultiIndex.from_arrays(
        [frame["speed"], frame["window"], ch, frame["feature"]]))
    xs = frame[is_x.to_numpy()]
    partner = pd.MultiIndex.from_arrays([xs["speed"], xs["window"],
                                         "y" + ch[is_x].str[1:], xs["feature"]])
    iy = pos.reindex(partner).to_numpy()
    ix = np.flatnonzero(is_x.to_numpy())
    has = ~np.isnan(iy)
    return ix[has], iy[has].astype(int)


def whirl_layout(index: pd.MultiIndex, tol_b: np.ndarray | None):
    """``(ix, iy, tol_b)``: the probe pairs' positions (:func:`whirl_pairs`) and each
    pair's backward-whirl tolerance (m); None without ``tol_b``."""
    if tol_b is None:
        return None
    ix, iy = whirl_pairs(index)
    return ix, iy, np.asarray(tol_b, dtype=float)[ix]


def circular_components(x, y):
    """A probe pair's two circular components ``((x + j y) / sqrt 2, (x - j y) / sqrt 2)``
    (complex 1x vectors, either sense of rotation); their sizes' sum of squares is
    ``|x|^2 + |y|^2``."""
    root2 = np.sqrt(2.0)
    return (x + 1j * y) / root2, (x - 1j * y) / root2


def _whirl_whitened(r_x, r_y, var_x, var_y, mtol_x, mtol_y, tol_b, S_x, S_y):
    """A probe pair's normalised 1x residuals, whitened in the whirl basis and rotated
    back onto the pair's two channels (their summed ``z2`` is the pair's).

    ``p = (x + j y) / sqrt 2`` and ``q = (x - j y) / sqrt 2`` are the orbit's two
    circular components; the larger of the model's is its forward whirl. Noise and the
    comparison's ``rtol`` are shared equally, as in the channel basis; the pair's 1x
    model-form tolerance (``mtol``: what the update's isotropic parameters left of the
    1x misfit) goes to the forward whirl alone, and the backward whirl is trusted only
    to ``tol_b``, the updated nominal model's own backward whirl. An axisymmetric rotor
    on like supports whirls forward; an ellipse (a support stiffer in one direction)
    is what its parameters cannot make, and at a disk far from the gravity-loaded
    contacts the model's ellipse is a tenth of a per cent of its orbit."""
    p, q = circular_components(r_x, r_y)
    s_p, s_q = circular_components(S_x, S_y)
    p_fwd = np.abs(s_p) >= np.abs(s_q)
    base = 0.5 * (var_x + var_y - mtol_x**2 - mtol_y**2)
    fwd, bwd = base + mtol_x**2 + mtol_y**2, base + tol_b**2
    var_p, var_q = np.where(p_fwd, fwd, bwd), np.where(p_fwd, bwd, fwd)
    dp = p / np.sqrt(np.maximum(var_p, 1e-300))
    dq = q / np.sqrt(np.maximum(var_q, 1e-300))
    return (dp + dq) / np.sqrt(2.0), -1j * (dp - dq) / np.sqrt(2.0)


def _normalised(Mc, Sc, se_m, se_s, order_k, speed_idx, group_idx, rtol, keyphasor_deg,
                harmonic_rtol, line_sigmas, model_tol=None, whirl=None, offset=None):
    """The one comparison kernel of :func:`compare` and :func:`fast_residual`:
    ``(M - S) / sigma`` per feature, complex, and the phase-aligned measured ``M``.

    Two phase alignments, each bounded by what it may absorb:

    * per speed step, the once-per-revolution reference's offset (the 1x phase
      difference over all channels, at most ``keyphasor_deg``), ``k`` times for order
      ``k``;
    * per channel (``group_idx``: speed step, window and channel), the integer
      harmonics (2x, 3x) by ``k`` times that channel's own remaining 1x phase
      difference, at most the phase its 1x model-form tolerance admits,
      ``arcsin(model_tol / |S_1x|)``. A contact nonlinearity's harmonics are locked to
      the orbit that makes them: where the model may be off in a journal's 1x phase,
      its harmonics there are off by ``k`` times as much, and counting that again would
      blame a candidate for the 1x model error the update already admitted. Where the
      1x tolerance is nil (a disk, an own-model plant) nothing turns.

    ``offset`` (complex, per feature; None: nothing) is the part of ``Sc`` that is no
    response of the rotor: a probe's constant runout vectors, which a candidate models
    exactly and the measurement holds as well. The difference ``M - Sc`` keeps it; every
    tolerance that scales with the prediction (``rtol``, ``harmonic_rtol``, the harmonics'
    turn and the whirl's sense) is taken of the rotor's part, ``Sc - offset`` and
    ``M - offset``. Taken of the whole, a 30 um runout beside a journal's 5 um orbit
    would widen that journal's 1x tolerance six-fold and its 2x tolerance to 0.3 of the
    runout's 2x, hiding from the comparison what the rotor beside the runout does.
    """
    lim = np.radians(keyphasor_deg)
    is1 = order_k == 1.0
    n_speeds = int(speed_idx.max()) + 1 if speed_idx.size else 0
    delta = np.angle(_per_group(speed_idx[is1], Mc[is1] * np.conj(Sc[is1]), n_speeds))
    # the keyphasor turns a probe's runout with the rotor's response: aligned as a whole
    M = Mc * np.exp(-1j * order_k * np.clip(delta, -lim, lim)[speed_idx])
    v = 0.0 if offset is None else offset
    R = Sc - v  # the rotor's response, what model-form tolerances are shares of
    tol = np.zeros(Mc.size) if model_tol is None else model_tol
    if np.any(tol[is1] > 0):
        n_groups = int(group_idx.max()) + 1
        d = np.zeros(n_groups)
        bound = np.zeros(n_groups)
        d[group_idx[is1]] = np.angle((M - v)[is1] * np.conj(R[is1]))
        bound[group_idx[is1]] = np.arcsin(np.clip(
            tol[is1] / np.maximum(np.abs(R[is1]), 1e-300), 0.0, 1.0))
        turn = np.clip(d, -bound, bound)[group_idx]
        # a runout's harmonic is fixed to the shaft, not locked to the orbit: it stays
        M = np.where(order_k >= 2.0, v + (M - v) * np.exp(-1j * order_k * turn), M)
    nons = order_k == 0.0
    harmonic = ~nons & ~is1
    noise = np.where(nons, (line_sigmas * se_m) ** 2 + (line_sigmas * se_s) ** 2,
                     se_m**2 + se_s**2)
    var = noise + (rtol * np.abs(R)) ** 2 + tol**2
    var = var + np.where(harmonic, (harmonic_rtol * np.minimum(np.abs(M - v), np.abs(R)))
                         ** 2, 0.0)
    d = (M - Sc) / np.sqrt(np.maximum(var, 1e-300))
    if whirl is not None and whirl[0].size:
        ix, iy, tol_b = whirl
        d[ix], d[iy] = _whirl_whitened(M[ix] - Sc[ix], M[iy] - Sc[iy], var[ix], var[iy],
                                       tol[ix], tol[iy], tol_b, R[ix], R[iy])
    return d, M


def feature_layout(index: pd.MultiIndex):
    """``(order_k, speed_idx, group_idx)`` of features indexed by ``speed, window,
    channel, feature``: each feature's order (0 for the non-synchronous lines), its
    speed step and its (speed step, window, channel) group."""
    frame = index.to_frame(index=False)
    order_k = frame["feature"].map(ORDER_K).fillna(0.0).to_numpy(dtype=float)
    speed_idx = pd.factorize(frame["speed"])[0]
    group_idx = pd.factorize(pd.MultiIndex.from_frame(frame[["speed", "window",
                                                             "channel"]]))[0]
    return order_k, speed_idx, group_idx


def probe_offsets(index: pd.MultiIndex, vectors: dict | None) -> np.ndarray | None:
    """Each feature's constant probe vector (complex, m) from ``vectors``, ``{channel:
    {order: complex}}`` (a fitted runout's, see ``ProbeRunout.order_vectors``), in the
    order of ``index`` (``speed, window, channel, feature``); 0 where a channel or
    order has none, None without ``vectors``."""
    if not vectors:
        return None
    frame = index.to_frame(index=False)
    order_k = frame["feature"].map(ORDER_K).fillna(0.0).to_numpy(dtype=float)
    channel = frame["channel"].astype(str).to_numpy()
    out = np.zeros(len(frame), complex)
    for ch, by_order in vectors.items():
        for k, v in by_order.items():
            out[(channel == ch) & (order_k == float(k))] = complex(v)
    return out


def comparison_layout(meas: pd.DataFrame, sim: pd.DataFrame, rule=None,
                      probe_vectors: dict | None = None) -> dict:
    """What :func:`compare` computes once for a pair of feature tables: the measured and
    simulated vectors ``M`` and ``S`` aligned row by row, each row's expected z2 under
    noise (``expect``: 2 for an order vector, 1 for a line energy), the rows' ``index``
    and the keyword arguments of :func:`fast_residual` but the two vectors."""
    key = ["speed", "window", "channel", "feature"]
    m = meas.set_index(key)
    s = sim.set_index(key).reindex(m.index)
    order_k, speed_idx, group_idx = feature_layout(m.index)
    kwargs = {"se_m": m["se"].to_numpy(), "se_s": s["se"].to_numpy(), "order_k": order_k,
              "speed_idx": speed_idx, "group_idx": group_idx, **tolerances(rule),
              "model_tol": model_tol(m), "whirl": whirl_layout(m.index, whirl_tol(m)),
              "offset": probe_offsets(m.index, probe_vectors)}
    return {"M": m["re"].to_numpy() + 1j * m["im"].to_numpy(),
            "S": s["re"].to_numpy() + 1j * s["im"].to_numpy(), "index": m.index,
            "expect": np.where(order_k == 0.0, 1.0, 2.0), "kwargs": kwargs}


def excess_of_residual(d: np.ndarray, layout: dict) -> np.ndarray:
    """Each feature's excess ``max(z2 - expect, 0)`` from :func:`fast_residual`'s
    residual ``d`` (real parts, then imaginary parts) and :func:`comparison_layout`."""
    n = d.size // 2
    return np.clip(d[:n] ** 2 + d[n:] ** 2 - layout["expect"], 0.0, None)


def compare(meas: pd.DataFrame, sim: pd.DataFrame, rule=None,
            probe_vectors: dict | None = None) -> pd.DataFrame:
    """Feature-by-feature gap between measured and simulated order features.

    The tolerances are ``rule``'s (:class:`~sknarx.gap.VerdictRule`; the default's when
    None); two records of one rotor (:mod:`sknarx.gap.passes`) have no model form
    between them and compare under a rule whose ``rtol`` and ``harmonic_rtol`` are 0.

    A ``model_tol`` column in ``meas`` (m) widens each feature's tolerance by the
    model-form error the nominal model is allowed (:mod:`sknarx.gap.tolerance`);
    harmonics agree to within ``harmonic_rtol`` and are compared in phase with their
    channel's 1x as far as its tolerance admits (``_normalised``). With a ``whirl_tol``
    column (m) each probe pair's 1x is compared in its forward and backward whirl, the
    1x model-form tolerance on the forward whirl only (``_whirl_whitened``); the table
    stays one row per channel.

    ``probe_vectors`` (``{channel: {order: complex}}``, m) are constant vectors ``sim``
    holds that are no response of the rotor -- a fitted probe runout's: the tolerances
    that scale with the simulation are taken of the rotor's part alone, so that a large
    runout does not widen them.
    """
    layout = comparison_layout(meas, sim, rule, probe_vectors)
    Mc, Sc = layout["M"], layout["S"]
    d, M = _normalised(Mc, Sc=Sc, **layout["kwargs"])
    z2 = np.abs(d) ** 2
    out = layout["index"].to_frame(index=False)
    out["measured"] = np.abs(Mc)
    out["simulated"] = np.abs(Sc)
    out["gap"] = np.abs(M - Sc)
    out["z2"] = z2
    out["excess"] = np.clip(z2 - layout["expect"], 0.0, None)
    return out


def fast_residual(Mc, Sc, **kwargs):
    """Normalised residuals of aligned feature arrays (the calibration's inner loop), as
    :func:`compare` computes them, real parts then imaginary parts; ``kwargs`` as
    :func:`comparison_layout` gives them (``model_tol`` in m per feature, ``whirl`` the
    probe pairs from :func:`whirl_layout` or None, ``offset`` the constant probe
    vectors ``Sc`` holds, complex, m, per feature, or None)."""
    d = _normalised(Mc, Sc=Sc, **kwargs)[0]
    return np.concatenate([d.real, d.imag])


def gap_statistic(cmp: pd.DataFrame) -> float:
    """Total excess gap (dimensionless, 0 when the two agree within noise)."""
    return float(cmp["excess"].sum())


def regions(cmp: pd.DataFrame, z_threshold: float) -> list[dict]:
    """Runs of adjacent speeds whose features' z2 exceeds ``z_threshold`` (the rule's
    :attr:`~sknarx.gap.VerdictRule.region_z2`), ranked by share of the total excess."""
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
