"""The order-domain front end: order-tracked Bode records against a linear rotor.

Most rotating-machinery users have order-tracked run-ups or coast-downs, not raw
time series. This front end diagnoses such a record (loaded and binned by
:mod:`sknarx.bode.records`) against a linear rotor described by a file
(:mod:`sknarx.rotor.beam`): its steady order response, or -- when the record is a
run-up too fast to be quasi-steady -- a simulated and order-tracked run-up
(:mod:`sknarx.rotor.runup`), through the order model of :mod:`sknarx.bode.model`.
The split, search, ranking, verdict and shrink are those of the time-series front end
(:mod:`sknarx.gap.search`, :class:`~sknarx.gap.VerdictRule`, :mod:`sknarx.gap.document`)
under :data:`~sknarx.gap.rule.ORDER_DOMAIN_RULE`; the report is written by the caller
(:func:`sknarx.bode.report.write_bode_outputs`).
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pandas as pd

from .._progress import phase
from ..gap.budget import SearchBudget
from ..gap.candidate import Candidate
from ..gap.document import ranking_entries, verdict_entries
from ..gap.evidence import alternating_split
from ..gap.floor import noise_floor
from ..gap.gapmap import regions, true_runs
from ..gap.result import GapDiagnosis
from ..gap.rule import ORDER_DOMAIN_RULE
from ..gap.search import FrontEnd, search
from ..rotor import EFFECTS
from ..rotor.beam import beam_rotor_from_config
from ..rotor.runup import damped_modes, sweep_parameter, transient_end_rpm
from .model import TRANSIENT_TOL, OrderModel, complex_pairs, fit_bearings, predict
from .model import Candidate as OrderCandidate
from .model import z2_of as _z2_of
from .records import RPM, bin_bode, load_bode, runup_rate

__all__ = ["load_bode", "bin_bode", "runup_rate", "diagnose_order_domain", "CANDIDATES"]

logger = logging.getLogger(__name__)

#: the effects a 1x order record can test against a linear rotor
CANDIDATES = ("runout", "anisotropy")
SWEEP_LIMIT = 0.1  # sweep parameter above which a run-up is simulated, not taken as steady
#: a bin's squared residual over its variance is chi-square with 2 degrees of freedom
#: when the model is right; above the rule's region point it counts as disagreeing
SIGNIFICANT_Z2 = ORDER_DOMAIN_RULE.region_z2
BLOCK_BINS = 3  # training and held-out bins alternate in blocks of this many
#: two training and two held-out blocks: the fewest bins on which a fit is judged where it
#: interpolates between the speeds it saw
MIN_BINS = 4 * BLOCK_BINS
# why the other effects cannot be tested on a 1x order record, whatever the rig (a rotor
# file's [report.untestable] adds what only its rig's owner knows)
_METHOD_LIMITS = {
    "speed-fluctuation": "its sidebands around 1x need the raw signal; order tracking "
                         "removes them",
    "noise": "characterised from the scatter of the order vectors, not a verdict",
}


def _untestable(cfg) -> list[dict]:
    """A ranking entry for each effect the record cannot test, with the reason."""
    rig = cfg.get("report", {}).get("untestable", {})
    out = []
    for name, cls in EFFECTS.items():
        if name in CANDIDATES:
            continue
        why = _METHOD_LIMITS.get(name, f"its signature ({cls.signature}) needs orders other "
                                       "than the 1x this record holds")
        if name in rig:
            why = f"{rig[name]}; {why}"
        out.append({"effect": name, "testable": False, "reason": why})
    return out


def z2_of(z, s, se):
    """Each bin's squared residual over its variance under the order-domain rule."""
    return _z2_of(z, s, se, ORDER_DOMAIN_RULE.rtol)


def _comparison(bins, z, s, se, sel, channel) -> pd.DataFrame:
    """The comparison table of the bins ``sel`` (one 1x feature per bin)."""
    z2 = z2_of(z, s, se)[sel]
    return pd.DataFrame({"speed": bins.speed.to_numpy()[sel], "window": "run-up",
                         "channel": channel, "feature": "1x",
                         "measured": np.abs(z[sel]), "simulated": np.abs(s[sel]),
                         "gap": np.abs(z - s)[sel], "z2": z2,
                         "excess": np.clip(z2 - 2.0, 0.0, None)})


def _regions(bins, z, s, se, noisy_rpm, channel):
    """The core's gap regions over every bin, with their speeds in rpm and whether they
    lie in the rotor file's noisy region."""
    every = np.ones(len(bins), dtype=bool)
    out = regions(_comparison(bins, z, s, se, every, channel), SIGNIFICANT_Z2)
    for r in out:
        r["rpm_range"] = [v / RPM for v in r["speed_range"]]
        r["noisy_region"] = bool(r["rpm_range"][0] > noisy_rpm)
    return out


class _BodeFrontEnd(FrontEnd):
    """Fits of the order model's candidates, each from the calibrated isotropic rotor."""

    def __init__(self, model, bins, train, held, bounds, start, s_cal, slow_rpm, channel):
        self.model, self.bins = model, bins
        self.train, self.held, self.bounds, self.start = train, held, bounds, start
        self.s_cal, self.slow_rpm, self.channel = s_cal, slow_rpm, channel
        self.rotor = model.rotor
        self.curves = {}  # each candidate's 1x at every bin (m), by its label

    def fit(self, names):
        return self._fit(OrderCandidate(runout="runout" in names,
                                        anisotropic="anisotropy" in names))

    def fit_pair(self, lead, partner):
        return self.fit((*lead.effects, partner))

    def _fit(self, cand):
        bins, train = self.bins, self.train
        z, se, sp = bins.z.to_numpy(), bins.se.to_numpy(), bins.speed.to_numpy()
        p, sd = fit_bearings(self.model, cand, bins, train, self.bounds, start=self.start)
        coef, s_all, kcs = predict(self.model, cand, p, sp[train], z[train], se[train], sp)
        rotor = self.rotor
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
            R = complex_pairs(coef)[-1]
            params.update(runout_amplitude_m=float(abs(R)), runout_phase_deg=float(
                np.degrees(np.angle(R))))
        cmp = _comparison(bins, z, s_all, se, self.held, self.channel)
        self.curves[json.dumps(cand.label)] = s_all
        # parameters beyond the calibrated nominal's two (isotropic stiffness, damping)
        n_added = len(p) + (2 if cand.runout else 0) - 2
        return Candidate(
            effects=cand.names, params=params, params_std=std, n_params=n_added,
            heldout_after=float(cmp["excess"].sum()), cmp=cmp,
            details={"evidence": _evidence(cand, bins, z, self.s_cal, s_all, params,
                                           self.slow_rpm),
                     "unbalance_kg_m": [[float(abs(u)), float(np.degrees(np.angle(u)))]
                                        for u in complex_pairs(coef)[: len(rotor.disks)]]},
            state=(cand, p))


def diagnose_order_domain(measured, cfg: dict, rule=None, budget=None) -> GapDiagnosis:
    """Diagnose a 1x Bode record against the linear rotor of a rotor file.

    Parameters
    ----------
    measured : path-like
        The order-tracked record: one row per revolution, columns named by the rotor
        file's ``[measurement]`` section (see :func:`sknarx.bode.records.load_bode`).
    cfg : dict
        The rotor file (:func:`sknarx.rotor.config.load_config`), ``model = "beam"``.
    rule : VerdictRule, optional
        The verdict's values (:data:`~sknarx.gap.rule.ORDER_DOMAIN_RULE` by default).
    budget : SearchBudget, optional
        Bootstrap resamples and seed (the rest of a budget does not apply here).

    Returns
    -------
    GapDiagnosis
        Reads like ``diagnosis.json`` (``verdict``, ``ranking``, ``where``, ``shrink``,
        ``nominal_calibration``, ``response_model``, ... see ``docs/gap.md``); its
        ``curves`` hold the binned record and the model curves the report draws. The
        report is written by the caller: :func:`sknarx.bode.report.write_bode_outputs`.

    Examples
    --------
    >>> from sknarx.datasets import load_rk4_runup
    >>> from sknarx.bode import diagnose_order_domain
    >>> from sknarx.rotor.config import load_config
    >>> cfg = load_config("examples/rk4/rotor.toml")  # doctest: +SKIP
    >>> diagnose_order_domain(load_rk4_runup().filename, cfg)["verdict"]  # doctest: +SKIP
    ['anisotropy', 'runout']
    """
    rule = rule or ORDER_DOMAIN_RULE
    budget = budget or SearchBudget(n_bootstrap=300)
    rotor, info = beam_rotor_from_config(cfg)
    meas_cfg = info["measurement"]
    if not info["probes"]:
        raise ValueError("The rotor file names no [[probes]]: give the probe the record was "
                         "taken at (name, position in m, direction 'x' or 'y').")
    probe = info["probes"][0]
    channel = probe.get("name", "probe")
    rows = load_bode(measured, meas_cfg)
    bins = bin_bode(rows)
    n = len(bins)
    if n < MIN_BINS:
        raise ValueError(
            f"The Bode record spans {n} speed bin(s) ({rows.rpm.min():.0f}-"
            f"{rows.rpm.max():.0f} rpm); at least {MIN_BINS} are needed, so that held-out "
            f"blocks of {BLOCK_BINS} lie between training ones: give a record over a wider "
            "speed range.")
    train = alternating_split(n, BLOCK_BINS)
    held = ~train
    mode = meas_cfg.get("response", "auto")
    if mode not in ("auto", "steady", "run-up"):
        raise ValueError(f"[measurement] response must be 'auto', 'steady' or 'run-up', got "
                         f"{mode!r}.")
    runup = runup_rate(rows) if mode != "steady" else None
    crit = meas_cfg.get("first_critical_rpm")
    model = OrderModel(rotor, probe, rtol=rule.rtol)
    limits = info["calibration"]
    bounds = (tuple(limits.get("bearing_stiffness", (1e5, 1e8))),
              tuple(limits.get("bearing_damping", (1.0, 2000.0))))
    z, se, sp = bins.z.to_numpy(), bins.se.to_numpy(), bins.speed.to_numpy()
    b0 = rotor.bearings[0]

    def evaluate(cand, p, on=None):
        coef, s_all, kcs = predict(on or model, cand, p, sp[train], z[train], se[train], sp)
        return coef, s_all, kcs, z2_of(z, s_all, se)

    def heldout(z2):
        return float(np.clip(z2[held] - 2, 0, None).sum())

    # the nominal model exactly as described (only the unbalance fitted)
    nominal = OrderCandidate(False, False)

    def nominal_excess(m, p):
        """Held-out excess of the effect-free rotor at bearings ``p`` on order model ``m``."""
        return heldout(evaluate(nominal, p, m)[3])

    p_nom = np.log10([b0.kxx, b0.cxx])
    _, s_nom, _, z2_nom = evaluate(nominal, p_nom)
    logger.info("%d revolutions in %d speed bins; calibrating the nominal rotor (steady "
                "response)", len(rows), n)
    with phase("nominal calibration"):
        cal = _calibrated_response(model, rotor, probe, runup, mode, bins, train, bounds,
                                   nominal, nominal_excess)
    model, p_cal, sd_cal, runup = cal["model"], cal["p"], cal["sd"], cal["runup"]
    coef_cal, s_cal, kcs_cal, z2_cal = evaluate(nominal, p_cal)
    cmp0 = _comparison(bins, z, s_cal, se, held, channel)
    E_before = float(cmp0["excess"].sum())
    n_held = int(held.sum())
    crit_cal = rotor.with_bearings(kxx=kcs_cal[0], kyy=kcs_cal[0]).natural_frequencies(2)
    # below ~3/4 of the first critical the response is small and a runout stands out
    slow_rpm = 0.75 * float(crit if crit else crit_cal[0] / RPM)

    front = _BodeFrontEnd(model, bins, train, held, bounds, (p_cal[0], p_cal[1]),
                          s_cal, slow_rpm, channel)
    logger.info("fitting the effect models to %d speed bins", n)
    ranked = search(front, CANDIDATES, E_before, cmp0, n_held, rule, budget)
    noisy = float(meas_cfg.get("noisy_above_rpm", np.inf))
    e0 = E_before / max(n_held, 1)
    # what the bins' own scatter leaves of the held-out gap (sknarx.gap.floor)
    floor = noise_floor(lambda m: np.clip(z2_of(m, s_cal, se)[held] - 2.0, 0.0, None),
                        s_cal, se, np.ones(n, dtype=bool), rule.false_alarm,
                        budget.n_bootstrap, budget.random_state)
    verdict = rule.decide(e0, ranked, floor, n_held)
    entries = ranking_entries(ranked, floor, n_held)
    for r in entries:
        r["located"] = _locate(r, ranking_fits=front.curves, s_cal=s_cal, bins=bins, z=z,
                               se=se, held=held, noisy_rpm=noisy)
    i_best = ranked.index(rule.preferred(ranked, floor, n_held)[0])
    best = entries[i_best]
    s_best = front.curves[json.dumps(best["effect"])]
    z2_best = z2_of(z, s_best, se)
    with phase("the verdict's response model"):
        response, s_quasi, until = _response_model(
            rotor, best, ranked[i_best].state[0], s_best, cal, mode, bins, train, bounds,
            crit_cal, noisy, z, se, sp, heldout)
    where = _regions(bins, z, s_cal, se, noisy, channel)
    doc = {
        "verdict": None,
        "ranking": entries + _untestable(cfg),
        "where": where,
        # where the corrected model still disagrees with the measurement, the same way
        "remaining": _regions(bins, z, s_best, se, noisy, channel),
        "significant_z2": SIGNIFICANT_Z2,
        "shrink": 0.0,
        "nominal_calibration": {
            "bearing_stiffness_N_per_m": {"nominal": b0.kxx, "calibrated": kcs_cal[0],
                                          "std": float(sd_cal[0] * np.log(10) * kcs_cal[0])},
            "bearing_damping_N_s_per_m": {"nominal": b0.cxx, "calibrated": kcs_cal[2],
                                          "std": float(sd_cal[-1] * np.log(10) * kcs_cal[2])},
            "first_critical_rpm": {"nominal": float(rotor.natural_frequencies(1)[0] / RPM),
                                   "calibrated": float(crit_cal[0] / RPM),
                                   "measured": meas_cfg.get("first_critical_rpm")},
            "unbalance_kg_m": [[float(abs(u)), float(np.degrees(np.angle(u)))] for u in
                               complex_pairs(coef_cal)],
        },
        "located": best.get("located", {}),
        "gap_by_band": _gap_by_band(bins, z2_cal, z2_best, held, noisy),
        "response_model": response,
        "gap_before": {"heldout_excess": E_before, "per_feature": e0,
                       "floor": floor.to_dict(),
                       "nominal_as_described_heldout_excess": heldout(z2_nom)},
        "split": {"bins": n, "train_bins": int(train.sum()), "heldout_bins": n_held,
                  "scheme": f"alternating blocks of {BLOCK_BINS} bins of 20 rpm"},
        "n_heldout_features": n_held,
        "limits": _limits(cfg, info, bins, noisy, runup, until),
        "settings": {"rule": rule.to_dict(), "budget": budget.to_dict()},
    }
    doc.update(verdict_entries(verdict, ranked, cmp0, where, rule, budget, n_held))
    modes = _verdict_modes(rotor, best)
    doc["critical_speeds_rpm"] = sorted(m["rpm"] for m in modes)
    doc["modes"] = modes
    sweep_info = (runup or cal["sweep_note"] or {})
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
    label = best["effect"] if isinstance(best["effect"], str) else " + ".join(best["effect"])
    curves = {"rows": rows, "bins": bins, "nominal": s_nom, "calibrated": s_cal,
              "corrected": s_best, "corrected_label": label, "quasi_steady": s_quasi,
              "z2": {"calibrated nominal": z2_cal, f"corrected ({label})": z2_best},
              "measurement": meas_cfg}
    # the rotor the effects were fitted on: the nominal with its calibrated bearings
    base = rotor.with_bearings(kxx=kcs_cal[0], kyy=kcs_cal[0], cxx=kcs_cal[2], cyy=kcs_cal[2])
    return GapDiagnosis(doc, front_end="order-domain", base=base, curves=curves,
                        tables={"before": cmp0, "after": ranked[i_best].cmp}, verdict=verdict)


def _calibrated_response(model, rotor, probe, runup, mode, bins, train, bounds, nominal,
                         nominal_excess) -> dict:
    """The nominal rotor's bearings calibrated on the training bins, and which response
    model they were calibrated on.

    A fast run-up is not a sequence of steady states: it is simulated (``mode``
    ``'run-up'``, or ``'auto'`` when the quasi-steady calibration's sweep parameter
    reaches :data:`SWEEP_LIMIT`), and the quasi-steady calibration is kept for the
    report's comparison. Returns the order model, the calibrated log10 bearings ``p``
    and their std ``sd``, ``runup`` (None unless simulated), ``sweep_note`` (a run-up
    found quasi-steady), ``steady`` (the quasi-steady model and calibration where the
    run-up is simulated) and ``base_choice`` (both models' effect-free held-out excess).
    """
    p_cal, sd_cal = fit_bearings(model, nominal, bins, train, bounds)
    out = {"model": model, "p": p_cal, "sd": sd_cal, "runup": runup, "sweep_note": None,
           "steady": None, "base_choice": None}
    if runup is None:
        return out
    k0, c0 = 10 ** p_cal[0], 10 ** p_cal[1]
    runup["sweep"] = sweep_parameter(rotor.with_bearings(kxx=k0, kyy=k0, cxx=c0, cyy=c0),
                                     runup["rate_rpm_s"])
    if mode != "run-up" and runup["sweep"]["sweep_parameter"] < SWEEP_LIMIT:
        return {**out, "sweep_note": runup, "runup": None}
    E_steady = nominal_excess(model, p_cal)
    swept = OrderModel(rotor, probe, runup, rtol=model.rtol)
    logger.info("run-up at %.0f rpm/s is not quasi-steady (sweep parameter %.2f): "
                "calibrating the simulated, order-tracked run-up", runup["rate_rpm_s"],
                runup["sweep"]["sweep_parameter"])
    p_run, sd_run = fit_bearings(swept, nominal, bins, train, bounds)
    return {**out, "model": swept, "p": p_run, "sd": sd_run, "steady": (model, p_cal),
            "base_choice": {"run-up model": nominal_excess(swept, p_run),
                            "quasi-steady model": E_steady}}


def _response_model(rotor, best, cand_best, s_best, cal, mode, bins, train, bounds,
                    crit_cal, noisy, z, se, sp, heldout):
    """The document's ``response_model``, the verdict's quasi-steady curve (None unless
    the run-up was simulated) and the speed (rpm) above which the run-up is steady
    (None likewise); ``best`` the judged candidate's ranking entry, ``cand_best`` its
    order-model candidate."""
    runup, sweep_note = cal["runup"], cal["sweep_note"]
    if runup is None:
        response = {"kind": "steady-state order response"}
        if sweep_note is not None:
            response.update(
                sweep=sweep_note["sweep"], rate_rpm_s=sweep_note["rate_rpm_s"],
                why="the run-up is slow enough to be quasi-steady (sweep parameter "
                f"{sweep_note['sweep']['sweep_parameter']:.3f} < {SWEEP_LIMIT})")
        return response, None, None
    until, _ = transient_end_rpm(_rotor_of(rotor, best["params"]), runup["rpm_start"],
                                 runup["rpm_end"], runup["rate_rpm_s"], TRANSIENT_TOL)
    # the same verdict on a quasi-steady model: how much the sweep itself matters
    logger.info("the verdict on a quasi-steady model, for comparison")
    steady_model, p_steady = cal["steady"]
    # started from the quasi-steady calibration, not the run-up one
    p_q, _ = fit_bearings(steady_model, cand_best, bins, train, bounds,
                          start=(p_steady[0], p_steady[1]))
    _, s_quasi, _ = predict(steady_model, cand_best, p_q, sp[train], z[train], se[train], sp)
    E_q = heldout(z2_of(z, s_quasi, se))
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
        # both calibrated, no effect added: what the sweep alone is worth on held-out bins
        "nominal_heldout_excess": cal["base_choice"],
    }
    return response, s_quasi, until


def _locate(r, ranking_fits, s_cal, bins, z, se, held, noisy_rpm=np.inf, thr=SIGNIFICANT_Z2,
            max_hole=2):  # r: a ranking entry of the document
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
        gain = z2_of(z, s_without, se) - z2_of(z, s_full, se)
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


def _evidence(cand, bins, z, s_before, s_after, params, slow_rpm):
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
