"""Which unmodelled effect causes the sim-to-real gap, and how far adding it shrinks it.

Procedure (all on order-domain features, see :mod:`sknarx.gap.features`):

1. Split the speed steps into training (every other step) and held-out steps.
2. Calibrate the nominal model's nuisance parameters (unbalance, stiffness and
   damping scales) on the training steps; the remaining held-out gap is the gap
   *before*. If it is within the noise floor, the verdict is ``no-gap``.
3. Calibrate every candidate effect (with the nuisances) on the training steps and
   measure the held-out gap *after*; rank by the after-gap plus a penalty of two
   per effect parameter (an AIC on the chi-square scale).
4. If the best single effect leaves a significant gap, probe every other candidate
   on top of its fit and pair it with the most promising ones (warm-started from its
   fit). Each member of the best pair is then re-fitted alone from the pair's fit, so
   that a pair is not credited with one member's convergence; the best pair replaces
   the best single if it removes most of what the single left.
5. The verdict is the best single effect or pair if it removes at least
   ``min_shrink`` of the held-out gap and ``min_log_shrink`` of its logarithm
   (a breadth check: see :func:`decide`), else ``unexplained``.

Thresholds are fixed on pilot trials of ``benchmarks/bench_gap_blind.py`` and
then frozen (see ``DiagnosisSettings``).
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import asdict

import numpy as np
import pandas as pd
from joblib import Parallel, delayed

from .._progress import progress_bar
from ..rotor import EFFECTS, RotorParameters, SimulationDivergenceError
from .calibration import NUISANCE, SweepModel, calibrate, discrete_settings, heldout_gap
from .features import TRANSIENT_RATIO, free_response_decay, is_nonsync, order_features
from .gapmap import HARMONIC_TOL, regions
from .settings import DiagnosisSettings
from .updating import linear_1x, update_nominal_model

__all__ = ["LIBRARY", "DiagnosisSettings", "diagnose"]

logger = logging.getLogger(__name__)


def _parallel(settings, jobs, total, desc):
    """Run ``jobs`` on threads with a progress bar (results in submission order)."""
    gen = Parallel(n_jobs=settings.n_jobs, prefer="threads", return_as="generator")(jobs)
    return list(progress_bar(gen, total=total, desc=desc, unit="fit"))

#: Candidate effects searched by default (measurement noise is characterised, not
#: searched: every measurement has some).
LIBRARY = ("rub", "misalignment", "crack", "looseness", "clearance", "anisotropy", "runout",
           "speed-fluctuation")


def _shrink(before, after):
    return float(1.0 - after / before) if before > 0 else 0.0


def _bootstrap_shrink(cmp_before, cmp_after, n, seed):
    """5-95 % band of the shrink, resampling held-out speed steps."""
    rng = np.random.default_rng(seed)
    b = cmp_before.groupby("speed")["excess"].sum()
    a = cmp_after.groupby("speed")["excess"].sum().reindex(b.index).fillna(0.0)
    speeds = b.index.to_numpy()
    vals = []
    for _ in range(n):
        pick = rng.choice(len(speeds), len(speeds), replace=True)
        sb, sa = b.to_numpy()[pick].sum(), a.to_numpy()[pick].sum()
        vals.append(_shrink(sb, sa))
    return [float(np.percentile(vals, 5)), float(np.percentile(vals, 95))]


def _evidence(cmp_before, cmp_after, k=3):
    """The features whose gap the candidate removed most (signature evidence)."""
    key = ["channel", "feature", "window"]
    b = cmp_before.groupby(key)["excess"].sum()
    a = cmp_after.groupby(key)["excess"].sum().reindex(b.index).fillna(0.0)
    gain = (b - a).sort_values(ascending=False)
    total = b.sum()
    out = []
    for (ch, feat, win), g in gain.head(k).items():
        if g <= 0:
            break
        out.append(f"{feat} at {ch} ({win}): {100 * g / total:.0f} % of the gap removed")
    return out


def _steady_1x(meas, speeds, channels):
    """Measured steady-window 1x vectors (m) and standard errors, (speeds, channels)."""
    m = meas[(meas.feature == "1x") & (meas.window == "steady")].set_index(
        ["speed", "channel"])
    idx = pd.MultiIndex.from_product([list(speeds), list(channels)])
    m = m.reindex(idx)
    shape = (len(speeds), len(channels))
    z = (m["re"].to_numpy() + 1j * m["im"].to_numpy()).reshape(shape)
    return z, m["se"].to_numpy().reshape(shape)


def _update_nominal(meas, train, channels, base, info, transient_s, settle_s, settings):
    """Nominal model updating on the training speeds' steady 1x, simulated over exactly
    the steady window the features were taken from. Each probe's constant vector is
    left out of it: a probe-specific vector the same at every speed is runout's to
    explain, not the rotor's parameters'."""
    z, se = _steady_1x(meas, train, channels)
    skip = int(round(transient_s * info["fs"]))
    # where the keyphasor sits on the shaft is arbitrary: the unbalance angle starts
    # from the measured 1x phase against the linearised nominal rotor's, so that the
    # update's prior on it is about the rig, not about the notch. Weighted by amplitude
    # (the largest responses decide), not by standard error: the journals' small 1x
    # has the smallest errors and the largest model-form phase error
    f0 = linear_1x(base, train, channels)
    dphi = float(np.angle(np.sum(z * np.conj(f0))))
    base = base.replace(unbalance_phase=float(np.angle(np.exp(1j * (base.unbalance_phase
                                                                    + dphi)))))
    logger.info("updating the nominal rotor's parameters on the steady 1x of %d training "
                "speeds", len(train))
    return update_nominal_model(
        z, np.maximum(se, 1e-12), train, channels, base=base,
        max_nfev=settings.update_max_nfev, remove_constant=True,
        nonlinear_kwargs={"fs": info["fs"], "n_samples": info["n_samples"] - skip,
                          "settle": settle_s + transient_s})


def _with_model_tolerance(meas, nominal, update, rtol=0.01):
    """The measured features with their model-form tolerance (m), fixed once from the
    updated nominal model's own features ``S``: for the 1x, what the update could not
    remove of each channel's misfit over the training speeds (``tau_c |S|`` beyond the
    comparison's ``rtol``; a constant per-probe vector excluded); for every harmonic and
    line, ``HARMONIC_TOL |S|``: the model's own harmonics come from a contact law no rig
    matches. What exceeds that is what effects must explain. ``nominal``: the updated
    nominal model's features at every speed."""
    key = ["speed", "window", "channel", "feature"]
    S = nominal.set_index(key).reindex(pd.MultiIndex.from_frame(meas[key]))
    size = np.hypot(S["re"].to_numpy(dtype=float), S["im"].to_numpy(dtype=float))
    tol = update.mismatch.get("model_tolerance", {}) if update is not None else {}
    extra = {c: float(np.sqrt(max(t * t - rtol * rtol, 0.0))) for c, t in tol.items()}
    share = np.where(meas["feature"] == "1x", meas["channel"].map(extra).fillna(0.0),
                     HARMONIC_TOL)
    out = meas.copy()
    out["model_tol"] = np.nan_to_num(share * size)
    return out


def _update_summary(update) -> dict | None:
    """The nominal update as plain JSON: what changed, how sure, what is inseparable."""
    if update is None:
        return None
    return {
        "updates": update.describe(),
        "parameters": update.table.to_dict(orient="records"),
        "inseparable_pairs": [{"a": a, "b": b, "correlation": c}
                              for a, b, c in update.correlated_pairs],
        "mismatch_1x": {k: v for k, v in update.mismatch.items() if k != "model_tolerance"},
        "model_tolerance_1x": update.mismatch.get("model_tolerance", {}),
        "chi2": update.cost,
        "method": "regularised toward nominal (log-scale priors), nonlinear steady 1x at "
                  "the training speeds, sensitivities from the linearised rotor",
    }


def diagnose(measured: pd.DataFrame, base: RotorParameters | None = None, channels=None,
             candidates=LIBRARY, settings: DiagnosisSettings | None = None,
             progress=None, exhaustive: bool = False) -> dict:
    """Diagnose a stepped-speed measurement against the nominal simulator.

    Parameters
    ----------
    measured : DataFrame
        Long table: ``speed`` (rad/s), ``t`` (s, 0 at each step's once-per-revolution
        reference) and one column per measured channel named after a DOF (m).
        See :func:`sknarx.gap.load_measured`.
    base : RotorParameters, optional
        Nominal rotor (the paper's by default).
    candidates : sequence of str
        Canonical effect names to search.

    Returns
    -------
    dict
        ``verdict``, ``ranking``, ``where``, ``shrink`` and the details (see
        ``docs/gap.md``); ``_tables`` holds the comparison tables for reports.
    """
    from .measured import check_measured

    settings = settings or DiagnosisSettings()
    tick = progress or logger.info
    unknown = [c for c in candidates if c not in EFFECTS]
    if unknown:
        raise ValueError(f"Unknown effect(s) {unknown}; the library has {', '.join(LIBRARY)}.")
    measured, info = check_measured(measured, channels)
    channels = info["channels"]
    base = base or RotorParameters()
    # transient or settled is read from the records, not assumed from their time axis:
    # settled records are compared with settled simulations and have no transient window
    decay = free_response_decay(measured, channels)
    starts_transient = bool(decay["transient"].median() >= 0.5)
    transient_s = settings.transient_s if starts_transient else 0.0
    settle_s = 0.0 if starts_transient else settings.settle_s
    speeds = np.array(info["speeds"])
    train, held = speeds[0::2], speeds[1::2]
    logger.info("%d speed steps x %d channel(s) at %.0f Hz (%s): extracting order features",
                speeds.size, len(channels), info["fs"],
                f"records start with a transient, first {transient_s:g} s kept apart"
                if starts_transient else "records are settled steady states")
    meas = order_features(measured, channels, transient_s)
    tick("measured order features")
    update = None
    if settings.update_nominal:
        update = _update_nominal(meas, train, channels, base, info, transient_s, settle_s,
                                 settings)
        base = update.params
        tick("nominal model updating")
    model = SweepModel(base=base, fs=info["fs"], n_samples=info["n_samples"],
                       channels=tuple(channels), transient_s=transient_s, settle_s=settle_s,
                       lead_s=settings.warm_lead_s)
    # the updated nominal model's features, simulated once: the model-form tolerance
    # reads them at every speed, the nuisance start at the training speeds
    nominal_all = model.features(speeds, np.array([v[3] for v in NUISANCE.values()]))
    meas = _with_model_tolerance(meas, nominal_all, update)
    logger.info("calibrating the nominal model's nuisance scalars on %d training speeds",
                train.size)

    # the nuisance-only model: start its unbalance phase from the 1x phase difference
    nominal = nominal_all[nominal_all.speed.isin(train)]
    m1 = meas[(meas.feature == "1x") & meas.speed.isin(train)]
    s1 = nominal.set_index(["speed", "window", "channel", "feature"]).reindex(
        pd.MultiIndex.from_frame(m1[["speed", "window", "channel", "feature"]]))
    dphi = float(np.angle(np.sum((m1.re.to_numpy() + 1j * m1.im.to_numpy())
                                 * np.conj(s1.re.to_numpy() + 1j * s1.im.to_numpy()))))
    start = np.array([1.0, dphi, 1.0, 1.0])
    cal0 = calibrate(model, meas, train, (), starts=[start], max_nfev=settings.max_nfev)
    E0, cmp0 = heldout_gap(model, meas, held, cal0, ())
    _, cmp_all = heldout_gap(model, meas, speeds, cal0, ())
    tick("nuisance calibration")
    e0 = E0 / max(len(cmp0), 1)
    n_features = max(len(cmp0), 1)
    result = {
        "verdict": None, "ranking": [], "where": regions(cmp_all),
        "shrink": 0.0,
        "gap_before": {"heldout_excess": E0, "per_feature": e0,
                       "rms_gap_m": float(np.sqrt(np.mean(cmp0["gap"] ** 2)))},
        "nuisance": {"calibrated": cal0.nuisance, "std": cal0.std},
        "noise": _noise_summary(meas),
        "split": {"train_speeds": train.tolist(), "heldout_speeds": held.tolist()},
        "sampling": {"fs_hz": info["fs"], "samples_per_step": info["n_samples"]},
        "records": {
            "starts_with_transient": starts_transient, "transient_window_s": transient_s,
            "simulation_settle_s": model.settle_s,
            "decay_ratio": decay["ratio"].tolist(), "decayed_s": decay["decayed_s"].tolist(),
            "rule": f"first-eighth residual RMS over the second half's > {TRANSIENT_RATIO:g} "
                    "on most steps: the records start with a transient"},
        "channels": list(channels),
        "settings": asdict(settings),
        "nominal_update": _update_summary(update),
    }
    tables = {"before": cmp0, "all": cmp_all}
    result["_base"] = base  # the updated nominal rotor (not in the JSON document)
    if e0 <= settings.no_gap_per_feature and not exhaustive:
        result["verdict"] = "no-gap"
        result["_tables"] = tables
        return result

    # the nuisance-only fit absorbs what it can of an effect (a crack's loss of mean
    # stiffness pulls the stiffness scale to 0.87, say) and a candidate started there
    # stays in that basin; candidates start from the rig's nominal stiffness and
    # damping instead (a rig's mismatch is a few per cent), with the fitted unbalance
    nuis_start = cal0.x.copy()
    nuis_start[[list(NUISANCE).index("stiffness_scale"),
                list(NUISANCE).index("damping_scale")]] = 1.0

    def _held(classes, names, cal):
        try:
            E, cmp = heldout_gap(model, meas, held, cal, classes)
        except SimulationDivergenceError:
            # calibrated on the training speeds, unstable at a held-out one: rejected
            E, cmp = float("inf"), None
        return names, cal, E, cmp

    def run(names):
        classes = [EFFECTS[n] for n in names]
        cal = calibrate(model, meas, train, classes, starts=[nuis_start],
                        max_nfev=settings.max_nfev, n_probe=settings.n_probe)
        return _held(classes, names, cal)

    logger.info("held-out gap %.3g per feature (no-gap floor %.3g): fitting %d effect "
                "candidate(s)", e0, settings.no_gap_per_feature, len(candidates))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        singles = _parallel(settings, (delayed(run)((c,)) for c in candidates),
                            len(candidates), "effect candidates")
    tick("single candidates")
    ranked = _rank(singles, E0, cmp0)
    best = ranked[0] if ranked else None
    pairs = []
    if best is not None:
        lead = best["_names"][0]
        lead_x = best["_cal"].x

        def continue_single():
            # a pair gets a warm-started run from the lead's fit; so does the lead, or a
            # partner would take the credit for the lead's own convergence. Done whether
            # or not pairs are tried, so the verdict does not depend on the pair trigger
            classes = [EFFECTS[lead]]
            cal = calibrate(model, meas, train, classes, starts=[lead_x],
                            max_nfev=settings.max_nfev, n_probe=0)
            return _held(classes, (lead,), cal)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            more = continue_single()
        if more[2] < best["_E"]:
            singles = [more if r[0] == (lead,) else r for r in singles]
            best = _rank(singles, E0, cmp0)[0]
        tick("lead continued")
    if best is not None and best["_E"] / n_features > settings.pair_trigger:
        # what the best single effect leaves is still a gap: pair it with every other
        # candidate, warm-started from the lead's first fit (only the partner is probed)

        # the leading effect keeps its discrete settings (a crack's station) in pairs
        lead_fixed = discrete_settings(best["_cal"], 0, EFFECTS[lead])

        def probe_partner(partner):
            # an effect masked by a dominant one fits badly on its own: score each
            # candidate by probing it on top of the leading fit instead
            cal = calibrate(model, meas, train, [EFFECTS[lead], EFFECTS[partner]],
                            starts=[lead_x], max_nfev=0, probe_from=len(lead_x),
                            fixed=[lead_fixed, None], n_probe=settings.n_probe)
            return cal.cost, partner

        def run_pair(partner):
            classes = [EFFECTS[lead], EFFECTS[partner]]
            cal = calibrate(model, meas, train, classes, starts=[lead_x],
                            max_nfev=settings.max_nfev, probe_from=len(lead_x),
                            fixed=[lead_fixed, None], n_probe=settings.n_probe)
            return _held(classes, (lead, partner), cal)

        def refit_member(names, pair_cal, member):
            # one member of a pair, on its own, started from the pair's fit
            x = pair_cal.x
            k = len(NUISANCE)
            width = [len(EFFECTS[n].bounds) for n in names]
            i = k + sum(width[:member])
            start = np.concatenate([x[:k], x[i : i + width[member]]])
            classes = [EFFECTS[names[member]]]
            cal = calibrate(model, meas, train, classes, starts=[start],
                            max_nfev=settings.max_nfev, n_probe=0,
                            fixed=[discrete_settings(pair_cal, member, classes[0])])
            return _held(classes, (names[member],), cal)

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            others = [c for c in candidates if c != lead]
            scores = _parallel(settings, (delayed(probe_partner)(c) for c in others),
                               len(others), f"partners of {lead}")
            partners = [p for _, p in sorted(scores)[: settings.n_partners]]
            pairs = _parallel(settings, (delayed(run_pair)(c) for c in partners),
                              len(partners), "pairs")
            # a pair must not take the credit for one member's convergence either (a
            # rub that found its basin only on top of a runout, a crack whose fit the
            # pair merely continued): each member of the best pair runs alone from it
            refits = []
            if pairs:
                top = _rank(pairs, E0, cmp0)[0]
                refits = _parallel(settings, (delayed(refit_member)(top["_names"],
                                                                    top["_cal"], m)
                                              for m in (0, 1)), 2, "pair members alone")
        for new in refits:
            singles = [new if old[0] == new[0] and new[2] < old[2] else old
                       for old in singles]
        tick("pairs")
    ranked_all = _rank(singles + pairs, E0, cmp0)
    choice = decide(e0, ranked_all, settings, n_features)
    if choice == "no-gap":
        result["verdict"] = "no-gap"
    elif choice is not None:
        names = choice["_names"]
        result["verdict"] = names[0] if len(names) == 1 else list(names)
        result["shrink"] = choice["_shrink"]
        result["shrink_band"] = _bootstrap_shrink(cmp0, choice["_cmp"], settings.n_bootstrap,
                                                  settings.seed)
        result["gap_after"] = {"heldout_excess": choice["_E"],
                               "rms_gap_m": float(np.sqrt(np.mean(choice["_cmp"]["gap"] ** 2)))}
        result["regions_after"] = _regions_after(result["where"], choice["_cmp"], cmp0)
        tables["after"] = choice["_cmp"]
    else:
        result["verdict"] = "unexplained"
        result["shrink"] = max(ranked_all[0]["_shrink"], 0.0) if ranked_all else 0.0
    result["n_heldout_features"] = n_features
    result["ranking"] = [{k: v for k, v in r.items() if not k.startswith("_")}
                         for r in ranked_all]
    result["_tables"] = tables
    return result


def decide(e0, ranking, settings, n_features):
    """The verdict from the held-out gap per feature and the ranked candidates.

    Returns ``'no-gap'``, the chosen ranking entry, or ``None`` (unexplained). Kept
    separate from the search so thresholds can be fixed on pilot trials and then
    applied unchanged to fresh ones.

    A candidate explains the gap when it removes ``min_shrink`` of the held-out
    excess *and* ``min_log_shrink`` of its logarithm: the excess is dominated by the
    few largest features, and an effect that matches them while breaking many
    others (a bearing rattling broadband to mimic an electrical line, say) must
    not pass. A pair replaces the best single only if the single leaves more than
    ``pair_trigger`` excess per feature and the pair removes ``pair_gain`` of it.
    """
    if e0 <= settings.no_gap_per_feature:
        return "no-gap"
    singles = [r for r in ranking if len(r["_names"]) == 1]
    pairs = [r for r in ranking if len(r["_names"]) == 2]
    if not singles:
        return None
    best = min(singles, key=lambda r: r["score"])
    choice = best
    if pairs and best["_E"] / n_features > settings.pair_trigger:
        pb = min(pairs, key=lambda r: r["score"])
        if pb["_E"] <= (1.0 - settings.pair_gain) * best["_E"]:
            choice = pb
    ok = (choice["_shrink"] >= settings.min_shrink
          and choice["log_shrink"] >= settings.min_log_shrink)
    return choice if ok else None


def _log_shrink(cmp0, cmp):
    if cmp is None:
        return -np.inf
    key = ["speed", "window", "channel", "feature"]
    b = cmp0.set_index(key)["excess"]
    a = cmp.set_index(key)["excess"].reindex(b.index).fillna(0.0)
    lb = np.log1p(b).sum()
    return float(1.0 - np.log1p(a).sum() / lb) if lb > 0 else 0.0


def _rank(results, E0, cmp0):
    out = []
    for names, cal, E, cmp in results:
        p_eff = cal.n_params - len(NUISANCE)
        shrink = _shrink(E0, E)
        out.append({
            "effect": names[0] if len(names) == 1 else list(names),
            "params": (_plain_params(names, cal.effect_params) if len(names) > 1 else
                       _plain_params(names, cal.effect_params)[0]),
            "params_std": {k: v for k, v in cal.std.items() if not k.startswith("nuisance")},
            "nuisance": cal.nuisance,
            "heldout_gap_before": E0, "heldout_gap_after": E, "shrink": shrink,
            "log_shrink": _log_shrink(cmp0, cmp),
            "score": E + 2.0 * p_eff,
            "evidence": _evidence(cmp0, cmp) if cmp is not None else
            ["the calibrated model diverges at a held-out speed"],
            "signature": [EFFECTS[n].signature for n in names],
            "_names": names, "_shrink": shrink, "_E": E, "_cmp": cmp, "_cal": cal,
        })
    out.sort(key=lambda r: r["score"])
    return out


def _plain_params(names, effect_params):
    """Each effect's fitted parameters as plain numbers (projected effects, such as the
    per-probe runout vectors, through their ``to_dict``)."""
    return [EFFECTS[n](**p).to_dict() if getattr(EFFECTS[n], "projected_orders", None)
            else p for n, p in zip(names, effect_params, strict=True)]


def _regions_after(where, cmp_after, cmp_before):
    out = []
    def select(c, r):
        lo, hi = r["speed_range"]
        return c[(c.channel == r["channel"]) & (c.feature == r["order"])
                 & (c.window == r["window"]) & (c.speed >= lo) & (c.speed <= hi)]

    for r in where:
        b = select(cmp_before, r)["excess"].sum()
        a = select(cmp_after, r)["excess"].sum()
        out.append({**r, "heldout_excess_before": float(b), "heldout_excess_after": float(a)})
    return out


def _noise_summary(meas):
    """Noise characterised from the data (measurement noise is never a verdict)."""
    nons = meas[meas.feature.map(is_nonsync)]
    one = meas[meas.feature == "1x"]
    amp = np.hypot(one.re, one.im)
    return {"median_1x_standard_error_m": float(np.median(one.se)),
            "median_1x_to_standard_error_db": float(
                20 * np.log10(np.median(amp) / max(np.median(one.se), 1e-30))),
            "median_white_floor_m": float(np.median(nons.se)),
            "median_line_energy_m": float(np.median(np.sqrt(
                (nons.re**2).groupby([nons.speed, nons.window, nons.channel]).sum())))}
