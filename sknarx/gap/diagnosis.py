"""The time-series front end: stepped-speed sweeps against the nonlinear simulator.

Procedure (all on order-domain features, see :mod:`sknarx.gap.features`); the split,
search, ranking, verdict and shrink are the gap core's (:mod:`sknarx.gap.core`):

1. Split the speed steps into training (every other step) and held-out steps.
2. Update the nominal rotor's linear parameters on the training steps' steady 1x
   (:mod:`sknarx.gap.updating`); each harmonic's and line's model-form tolerance
   carries what the update left uncertain (its spread over the update's sigma
   points). Then calibrate the nuisance parameters (unbalance, stiffness and damping
   scales); the remaining held-out gap is the gap *before*. If it is within the noise
   floor, and so is each of its 1x, 2x and 3x features' mean on its own
   (:func:`sknarx.gap.core.orders_over_floor`), the verdict is ``no-gap``.
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
   (a breadth check, waived where it leaves no more than the no-gap floor: see
   :func:`sknarx.gap.core.decide`), else ``unexplained``.

Thresholds are set on trials of ``benchmarks/bench_gap_blind.py`` and then frozen
(see ``DiagnosisSettings``; docs/gap.md tables which trials set each).
"""

from __future__ import annotations

import dataclasses
import logging
import warnings
from dataclasses import asdict

import numpy as np
import pandas as pd

from .._progress import progress_bar
from ..rotor import EFFECTS, RotorParameters, SimulationDivergenceError
from .calibration import (
    NUISANCE,
    SweepModel,
    calibrate,
    discrete_settings,
    effect_blocks,
    heldout_gap,
    search_vector,
)
from .checkpoint import Checkpoint, NoCheckpoint
from .core import (
    CandidateFit,
    FrontEnd,
    alternating_split,
    conclude,
    decide,
    order_floors,
    order_mean_z2,
    orders_over_floor,
    public_ranking,
    rank,
    recheck_choice,
    run_parallel,
    search,
    setting_support,
    table_evidence,
    with_passes,
)
from .features import TRANSIENT_RATIO, free_response_decay, is_nonsync, order_features
from .gapmap import HARMONIC_TOL, circular_components, regions, whirl_pairs
from .passes import compare_passes
from .readings import check_readings, reading_contenders
from .result import GapDiagnosis
from .settings import DiagnosisSettings
from .updating import linear_1x, update_nominal_model

__all__ = ["LIBRARY", "DiagnosisSettings", "diagnose"]

logger = logging.getLogger(__name__)

#: Candidate effects searched by default (measurement noise is characterised, not
#: searched: every measurement has some).
LIBRARY = ("rub", "misalignment", "crack", "looseness", "clearance", "anisotropy", "runout",
           "speed-fluctuation")


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
                          "settle": settle_s + transient_s,
                          "step_factor": settings.step_factor})


def _prediction_spread(model, speeds, update, nominal, nuis):
    """Each feature's spread (m) over what the update left uncertain, aligned with
    ``nominal`` (the updated rotor's features), and the number of principal directions.

    The spread is the root of a second moment about the updated rotor's features: half
    the squared vector difference at each of its sigma points
    (:meth:`~sknarx.gap.updating.UpdateResult.sigma_points`, an unscented transform on
    the posterior's axes), plus the whole squared difference to the rotor before the
    update. The update is fitted to the steady 1x; the bearings' contact stiffness and
    clearance barely touch the 1x but decide the journals' harmonics, by their own size
    where the orbit is about to unload the contact every revolution, and what the update
    did to a prediction no data it saw checked is no less uncertain than the change it
    made. A model that cannot predict a feature cannot blame an effect for it."""
    # same model, speeds and nuisances: the features come in ``nominal``'s order
    z0 = nominal["re"].to_numpy() + 1j * nominal["im"].to_numpy()
    var = np.zeros(z0.size)
    points = update.sigma_points()
    failed = 0
    runs = [(p, 0.5) for pair in points for p in pair] + [(update.nominal, 1.0)]
    for params, weight in progress_bar(runs, desc="update uncertainty", unit="sweep"):
        try:
            _, z, _, _ = dataclasses.replace(model, base=params).feature_arrays(speeds, nuis)
        except SimulationDivergenceError:
            failed += 1
            continue
        var += weight * np.nan_to_num(np.abs(np.asarray(z) - z0) ** 2)
    if failed:
        logger.warning("%d of the update's %d sigma points diverged: the model's "
                       "prediction spread leaves them out", failed, 2 * len(points))
    return np.sqrt(var), len(points)


def _common_1x_tolerance(update) -> dict:
    """Each channel's 1x model-form tolerance (relative): the smaller of its own misfit
    after the update and its probe partner's (``yA`` for ``xA``).

    The update's parameters are those of an axisymmetric rotor on like supports: what
    they cannot follow shows in both directions of a probe pair, and that common part is
    model-form error. What one direction has beyond the other -- a split the isotropic
    parameters cannot make -- is an anisotropy's signature and is left for an effect to
    explain; taken as tolerance it hides soft pedestals (measured in docs/gap.md). A
    channel without a partner keeps its own."""
    if update is None:
        return {}
    own = update.mismatch.get("model_tolerance", {})
    swap = {"x": "y", "y": "x"}
    return {c: min(t, own.get(swap.get(c[0], c[0]) + c[1:], t)) for c, t in own.items()}


def _with_model_tolerance(meas, nominal, update, spread=None, rtol=0.01):
    """The measured features with their model-form tolerance (m), fixed once from the
    updated nominal model's own features ``S``: for the 1x, what the update could not
    remove of the misfit over the training speeds that both channels of a probe pair
    share (``tau_c |S|`` beyond the comparison's ``rtol``, :func:`_common_1x_tolerance`;
    a constant per-probe vector excluded); for every harmonic and
    line, ``HARMONIC_TOL |S|`` -- the model's own harmonics come from a contact law no
    rig matches -- and, in quadrature, ``spread``: the feature's spread over the
    update's uncertainty (:func:`_prediction_spread`, aligned with ``nominal``). What
    exceeds that is what effects must explain. A ``whirl_tol`` column adds each probe
    pair's backward-whirl tolerance (:func:`_backward_whirl`): the 1x tolerance above
    then admits a larger or smaller circle, not an ellipse. ``nominal``: the updated
    nominal model's features at every speed."""
    key = ["speed", "window", "channel", "feature"]
    nominal = nominal.copy()
    nominal["spread"] = 0.0 if spread is None else spread
    S = nominal.set_index(key).reindex(pd.MultiIndex.from_frame(meas[key]))
    size = np.hypot(S["re"].to_numpy(dtype=float), S["im"].to_numpy(dtype=float))
    tol = _common_1x_tolerance(update)
    extra = {c: float(np.sqrt(max(t * t - rtol * rtol, 0.0))) for c, t in tol.items()}
    is1 = (meas["feature"] == "1x").to_numpy()
    share = np.where(is1, meas["channel"].map(extra).fillna(0.0), HARMONIC_TOL)
    widen = np.where(is1, 0.0, np.nan_to_num(S["spread"].to_numpy(dtype=float)))
    out = meas.copy()
    out["model_tol"] = np.nan_to_num(np.hypot(share * size, widen))
    out["whirl_tol"] = _backward_whirl(S)
    return out


def _backward_whirl(S):
    """Each probe pair's backward-whirl tolerance (m) on both of its 1x rows: the
    smaller circular component of the updated nominal model's own 1x orbit, ``|x - j y|
    / sqrt 2`` or ``|x + j y| / sqrt 2`` (0 elsewhere). The model's ellipse comes from its
    gravity-loaded contacts, whose anisotropy no rig matches, and is trusted to its
    own size as its harmonics are (``HARMONIC_TOL``); what a support stiffer in one
    direction adds beyond it is an effect's to explain (see ``gapmap.compare``). ``S``:
    the nominal model's features aligned with the measured rows."""
    ix, iy = whirl_pairs(S.index)
    z = S["re"].to_numpy(dtype=float) + 1j * S["im"].to_numpy(dtype=float)
    p, q = circular_components(z[ix], z[iy])
    b = np.minimum(np.abs(p), np.abs(q))
    out = np.zeros(len(S))
    out[ix] = out[iy] = HARMONIC_TOL * np.nan_to_num(b)
    return out


def _whirl_summary(meas) -> dict:
    """Each probe pair's backward-whirl tolerance (the ``whirl_tol`` column of
    :func:`_with_model_tolerance`) over the speeds, median and largest (m), and the rule."""
    key = ["speed", "window", "channel", "feature"]
    ix, iy = whirl_pairs(pd.MultiIndex.from_frame(meas[key]))
    rows = meas.iloc[ix]
    label = rows["channel"].to_numpy() + "/" + meas["channel"].to_numpy()[iy]
    pairs = {k: {"median_m": float(g.median()), "max_m": float(g.max())}
             for k, g in rows["whirl_tol"].groupby(label)}
    return {"pairs": pairs,
            "rule": "each probe pair's 1x is compared in its forward and backward whirl: "
                    "the 1x model-form tolerance admits a larger or smaller circle "
                    "(forward whirl) only; the orbit's ellipse (backward whirl) is "
                    "trusted to the updated nominal model's own"}


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
        "model_tolerance_1x": _common_1x_tolerance(update),
        "channel_misfit_1x": update.mismatch.get("model_tolerance", {}),
        "chi2": update.cost,
        "method": "regularised toward nominal (log-scale priors), nonlinear steady 1x at "
                  "the training speeds, sensitivities from the linearised rotor",
    }


_SETTING_KEYS = ("discrete_settings", "setting_decided")


def _setting_key(setting) -> tuple:
    """A discrete-setting row's ``setting`` ({effect: {name: value}}) as a dict key."""
    return tuple((n, tuple(sorted(d.items()))) for n, d in sorted(setting.items()))


def _setting_rows(fits, settings):
    """A candidate's discrete-setting entries from ``(setting, fit, refitted)`` per
    setting, the chosen one first: each setting's held-out excess and training cost
    and, for the others, how often the held-out speeds prefer the chosen one
    (``refitted``: refitted from the chosen candidate's fit, see ``recheck_setting``)."""
    best = fits[0][1]
    rows = [{"setting": setting, "heldout_gap_after": f.heldout_excess,
             "training_cost": f.state.cost,
             **({"from_chosen_fit": True} if refitted else {}),
             **({} if f is best or best.cmp is None else {"chosen_preferred_share":
                 setting_support(best.cmp, f.cmp, settings.n_bootstrap, settings.seed)})}
            for setting, f, refitted in fits]
    return _setting_evidence(rows, settings.decided_setting_support)


def _setting_evidence(rows, level):
    """A candidate's discrete-setting entries: the rows (chosen first) and whether the
    held-out speeds prefer the chosen setting over every other in ``level`` of their
    bootstrap resamples."""
    shares = [r["chosen_preferred_share"] for r in rows[1:] if "chosen_preferred_share" in r]
    return {"discrete_settings": rows,
            "setting_decided": bool(shares) and min(shares) >= level}


class _SweepFrontEnd(FrontEnd):
    """The time-series front end's fits: the nonlinear simulator (with the nuisance
    scalars) calibrated on the training speeds' order features."""

    def __init__(self, model, meas, train, held, cmp0, settings, nuis_start, checkpoint):
        self.model, self.meas, self.train, self.held = model, meas, train, held
        self.cmp0, self.settings, self.nuis_start = cmp0, settings, nuis_start
        # each calibration and held-out comparison is a step a rerun reads back
        # (a NoCheckpoint computes every one)
        self.checkpoint = checkpoint
        self._lead_x = None
        # each probe's cost by effects, discrete settings and point: a pair's probes
        # are its partner's probes on top of the lead, scored once
        self._probe_costs = {}
        # each candidate's fit per discrete setting, best first: a pair member's refit
        # takes its single's evidence from it, the verdict's recheck its other settings
        self._setting_fits = {}

    def _result(self, names, cal, classes=None):
        """The candidate fit of ``cal``; with ``classes``, those it calibrated, where a
        class not named in ``names`` is the linear form of a member (model error)."""
        classes = list(classes) if classes is not None else [EFFECTS[n] for n in names]
        E, cmp = self.checkpoint.step(
            "heldout", [self.model, self.held, classes, cal],
            lambda: _heldout_or_diverged(self.model, self.meas, self.held, cal, classes))
        plain = _plain_params(classes, cal.effect_params)
        params = [p for c, p in zip(classes, plain, strict=True) if c.name in names]
        error = {c.name: p for c, p in zip(classes, plain, strict=True) if c.name not in names}
        details = {"nuisance": cal.nuisance,
                   "evidence": table_evidence(self.cmp0, cmp) if cmp is not None else
                   ["the calibrated model diverges at a held-out speed"],
                   "signature": [EFFECTS[n].signature for n in names]}
        if error:
            details["model_error"] = error
        return CandidateFit(
            names=tuple(names), params=params[0] if len(names) == 1 else params,
            params_std={k: v for k, v in cal.std.items() if not k.startswith("nuisance")},
            n_params=cal.n_params - len(NUISANCE), heldout_excess=E, cmp=cmp,
            details=details, state=cal)

    def _calibrate(self, names, classes=None, **kw):
        classes = classes if classes is not None else [EFFECTS[n] for n in names]
        kw = {"max_nfev": self.settings.max_nfev,
              "jacobian_refresh": self.settings.jacobian_refresh,
              "settled_sigma": self.settings.settled_sigma,
              "probes_per_parameter": self.settings.probes_per_parameter, **kw}
        # the probe cache only saves work, it changes no result: not part of the key
        return self.checkpoint.step(
            "calibrate", [self.model, self.train, list(classes), kw],
            lambda: calibrate(self.model, self.meas, self.train, classes,
                              probe_cache=self._probe_costs, **kw))

    def _best(self, names, **kw):
        # each discrete setting (a crack's station, a rub's disk) converged on the
        # training speeds and chosen, as candidates are, on the held-out ones: the
        # training cost barely tells stations apart (see calibrate)
        fits = sorted((self._result(names, cal)
                       for cal in self._calibrate(names, each_discrete=True, **kw)),
                      key=lambda f: (f.heldout_excess, f.state.cost))
        if len(fits) > 1:
            # what the data say about the setting: each one's held-out excess and how
            # often a bootstrap over the held-out speeds prefers the chosen one, so a
            # setting the held-out speeds barely separate is seen as such
            classes = [EFFECTS[n] for n in names]
            settings = [{c.name: discrete_settings(f.state, i, c)
                         for i, c in enumerate(classes) if c.discrete} for f in fits]
            fits[0].details.update(_setting_rows(
                [(st, f, False) for st, f in zip(settings, fits, strict=True)],
                self.settings))
            # best first (dicts keep their order): the single's evidence is its first's
            self._setting_fits[names] = {_setting_key(st): f
                                         for st, f in zip(settings, fits, strict=True)}
        return fits[0]

    def fit(self, names):
        return self._best(names, starts=[self.nuis_start], n_probe=self.settings.n_probe)

    def continue_fit(self, fit):
        # pairs start from the lead's first fit, whatever its continuation does; the
        # continuation keeps the fit's discrete settings
        self._lead_x = fit.state.x
        fixed = [discrete_settings(fit.state, i, EFFECTS[n]) for i, n in enumerate(fit.names)]
        more = self._result(fit.names, self._calibrate(fit.names, starts=[fit.state.x],
                                                       n_probe=0, fixed=fixed))
        # the setting was chosen by the first fit; its evidence stays with the candidate
        more.details.update({k: fit.details[k] for k in _SETTING_KEYS if k in fit.details})
        return more

    def _pair_kw(self, lead):
        # only the partner is probed; the lead keeps its discrete settings (a crack's
        # station) and starts from its first fit. The partners' probes and the pairs'
        # fits share these keywords: a pair reuses its partner's probe costs
        x0 = self._lead_x if self._lead_x is not None else lead.state.x
        return {"starts": [x0], "probe_from": len(x0), "n_probe": self.settings.n_probe,
                "probes_per_parameter": self.settings.pair_probes_per_parameter,
                "n_short": self.settings.pair_short_starts,
                "fixed": [discrete_settings(lead.state, 0, EFFECTS[lead.names[0]]), None]}

    def partners(self, lead, others, k):
        # an effect masked by a dominant one fits badly on its own: score each
        # candidate by probing it on top of the leading fit instead
        costs = run_parallel(self.settings.n_jobs, [
            lambda p=p: self._calibrate((lead.names[0], p), max_nfev=0,
                                        **self._pair_kw(lead)).cost for p in others],
            f"partners of {lead.names[0]}")
        return [p for _, p in sorted(zip(costs, others, strict=True))[:k]]

    def fit_pair(self, lead, partner):
        return self._best((lead.names[0], partner), **self._pair_kw(lead))

    def refit_members(self, pair):
        # a pair must not take the credit for one member's convergence either (a rub
        # that found its basin only on top of a runout, a crack whose fit the pair
        # merely continued): each member runs alone from the pair's fit
        x = pair.state.x
        k = len(NUISANCE)
        blocks = effect_blocks(x, [EFFECTS[n] for n in pair.names])
        out = []
        for member in (0, 1):
            name = pair.names[member]
            start = np.concatenate([x[:k], blocks[member]])
            setting = discrete_settings(pair.state, member, EFFECTS[name])
            cal = self._calibrate((name,), starts=[start], n_probe=0, fixed=[setting])
            refit = self._result((name,), cal)
            # the member's setting came from the pair: its single's evidence holds
            # only where the single chose the same one
            first = next(iter(self._setting_fits.get((name,), {}).values()), None)
            single = first.details if first is not None else None
            if single is not None:
                same = single["discrete_settings"][0]["setting"].get(name) == setting
                refit.details.update({"discrete_settings": single["discrete_settings"],
                                      "setting_decided": same and single["setting_decided"]})
            out.append(refit)
        return out

    def recheck_setting(self, fit):
        # each other setting's own search started from its probes and may have missed
        # the basin the chosen one found; started from the chosen fit it may reach it
        # (a rub at one of two disks that a stiff joint couples) or do better (measured
        # in docs/gap.md, "Where the verdict acts")
        rows = fit.details.get("discrete_settings")
        if not rows:
            return None
        classes = [EFFECTS[n] for n in fit.names]
        chosen = {c.name: discrete_settings(fit.state, i, c)
                  for i, c in enumerate(classes) if c.discrete}
        own = self._setting_fits.get(fit.names, {})
        reps = {_setting_key(chosen): (chosen, fit, False)}
        for row in rows:
            key = _setting_key(row["setting"])
            if key in reps:
                continue
            fixed = [row["setting"].get(c.name) if c.discrete else None for c in classes]
            again = self._result(fit.names, self._calibrate(
                fit.names, starts=[fit.state.x], n_probe=0, fixed=fixed))
            first = own.get(key)
            better_first = first is not None and first.heldout_excess <= again.heldout_excess
            reps[key] = ((row["setting"], first, False) if better_first
                         else (row["setting"], again, True))
        # a model-error member (the linear-form test) is not refitted with the setting:
        # such a verdict keeps its setting and only learns how firmly it was chosen
        movable = not fit.details.get("model_error")
        best_key = min(reps, key=lambda k: reps[k][1].heldout_excess) if movable else \
            _setting_key(chosen)
        best = reps[best_key][1]
        others = sorted((v for k, v in reps.items() if k != best_key),
                        key=lambda v: v[1].heldout_excess)
        entries = _setting_rows([reps[best_key], *others], self.settings)
        if best is fit:
            return entries, None
        # another setting fits the held-out speeds better: it replaces the verdict's fit
        return entries, best

    def linear_forms(self, fit):
        # the member's linear form starts from its fitted instance, the others keep
        # their fit and discrete settings: only the restriction is tested
        k = len(NUISANCE)
        classes = [EFFECTS[n] for n in fit.names]
        blocks = effect_blocks(fit.state.x, classes)
        out = []
        for i, cls in enumerate(classes):
            if cls.linear_form is None:
                continue
            form = cls.from_params(fit.state.effect_params[i]).linear_form_of()
            swapped = [*classes[:i], cls.linear_form, *classes[i + 1:]]
            start = np.concatenate([fit.state.x[:k], *blocks[:i],
                                    search_vector(form), *blocks[i + 1:]])
            fixed = [None if j == i else discrete_settings(fit.state, j, c)
                     for j, c in enumerate(classes)]
            cal = self._calibrate(fit.names, swapped, starts=[start], n_probe=0, fixed=fixed)
            out.append(self._result(fit.names[:i] + fit.names[i + 1:], cal, swapped))
        return out


def diagnose(measured: pd.DataFrame, base: RotorParameters | None = None, channels=None,
             candidates=LIBRARY, settings: DiagnosisSettings | None = None,
             progress=None, exhaustive: bool = False, readings=None,
             second_pass: pd.DataFrame | None = None, checkpoint=None) -> GapDiagnosis:
    """Diagnose a stepped-speed measurement against the nominal simulator.

    Parameters
    ----------
    measured : DataFrame
        Long table: ``speed`` (rad/s), ``t`` (s, 0 at each step's once-per-revolution
        reference) and one column per measured channel named after a DOF (m).
        See :func:`sknarx.gap.load_measured`.
    base : RotorParameters, optional
        Nominal rotor (the paper's by default).
    channels : sequence of str, optional
        Channels to compare (every DOF column by default).
    candidates : sequence of str
        Canonical effect names to search.
    settings : DiagnosisSettings, optional
        Thresholds and search effort (the frozen defaults by default).
    progress : callable, optional
        Called with a short message after each phase (default: the package logger).
    exhaustive : bool
        Search the candidates even when the gap is within the noise floor.
    readings : mapping, optional
        Alternative readings of the nominal rotor, ``{label: {parameter: value}}``
        (:class:`~sknarx.rotor.RotorParameters` fields in SI units): model-form choices
        the rotor's description leaves open, such as ``{"joint dampers on the disks'
        tilt": {"tilt_share_O": 1.0}}``. Each is a discrete setting of the rotor the
        data choose on the held-out speeds (:mod:`sknarx.gap.readings`); the reading of
        the verdict is reported as model error (``rotor_reading``). None: the rotor as
        given only.
    second_pass : DataFrame, optional
        A second pass of the same sweep in the same format, e.g. the coast-down after
        the run-up. It is compared with ``measured`` first, model-free
        (:func:`sknarx.gap.passes.compare_passes`). Where the two differ beyond their
        noise floor, the rotor changed between them. No candidate of the library, each
        time-invariant, explains that, so the verdict is ``unexplained``, and
        ``passes`` says where the passes differ and what ``measured`` alone concluded
        (:func:`sknarx.gap.core.with_passes`). The candidates are fitted to
        ``measured`` alone.
    checkpoint : str or Path, optional
        A directory that keeps each finished step (the nominal update, its prediction
        spread, every calibration and held-out comparison), written whole or not at all
        (:mod:`sknarx.gap.checkpoint`). A rerun on the same inputs reads them back, so a
        stopped diagnosis resumes where it stopped and gives the same result as an
        uninterrupted run; a rerun with other data, rotor, settings, candidates,
        readings, package source or dependency versions starts the directory over.
        The directory is kept afterwards (a rerun then takes seconds); delete it when
        done. None: nothing is kept.

    Returns
    -------
    GapDiagnosis
        Reads like ``diagnosis.json``: ``verdict``, ``ranking``, ``where``, ``shrink``
        and the details (see ``docs/gap.md``); its ``tables`` hold the comparison
        tables and its ``base`` the updated nominal rotor. The report is written by
        the caller: :func:`sknarx.gap.report.write_gap_outputs`.

    Examples
    --------
    >>> from sknarx.gap import diagnose
    >>> from sknarx.testing import make_trial
    >>> measured, truth = make_trial("none", seed=0)  # doctest: +SKIP
    >>> diagnose(measured)["verdict"]  # doctest: +SKIP
    'no-gap'
    """
    from threadpoolctl import threadpool_limits

    # each evaluation runs its speeds on two threads; a BLAS that threads its small
    # solves as well (the features' least squares) fights them for the two cores:
    # measured, one evaluation of 10 speeds 50 ms with one BLAS thread, 100 ms with two
    with threadpool_limits(limits=1, user_api="blas"):
        passes = None
        if second_pass is not None:
            # model-free and cheap: a rotor that changed between passes is said so even
            # where the search then names a time-invariant effect for the first pass
            passes = compare_passes(measured, second_pass, channels, settings)
            logger.info("second pass against the first: a normal deviate of %.3g beyond "
                        "the dead band (floor %.3g): %s", passes.statistic, passes.floor,
                        "the rotor changed between the passes" if passes.changed
                        else "the passes agree")
        readings = check_readings(readings, base)
        kept = NoCheckpoint()
        if checkpoint is not None:
            kept = Checkpoint(checkpoint, {
                "measured": measured, "base": base, "channels": channels,
                "candidates": list(candidates), "settings": settings,
                "exhaustive": exhaustive, "readings": readings})
        result = _diagnose(measured, base, channels, candidates, settings, progress,
                           exhaustive, readings, kept)
        if checkpoint is not None:
            logger.info("checkpoint %s: %d step(s) read back, %d computed", checkpoint,
                        kept.reused, kept.computed)
        return with_passes(result, passes)


def _diagnose(measured, base, channels, candidates, settings, progress, exhaustive,
              readings, kept):
    from .measured import check_measured

    settings = settings or DiagnosisSettings()
    tick = progress or logger.info
    unknown = [c for c in candidates if c not in EFFECTS]
    if unknown:
        raise ValueError(f"Unknown effect(s) {unknown}; the library has {', '.join(LIBRARY)}.")
    measured, info = check_measured(measured, channels)
    channels = info["channels"]
    base = nominal_base = base or RotorParameters()
    # transient or settled is read from the records, not assumed from their time axis:
    # settled records are compared with settled simulations and have no transient window
    decay = free_response_decay(measured, channels)
    starts_transient = bool(decay["transient"].median() >= 0.5)
    transient_s = settings.transient_s if starts_transient else 0.0
    settle_s = 0.0 if starts_transient else settings.settle_s
    speeds = np.array(info["speeds"])
    is_train = alternating_split(speeds.size)
    train, held = speeds[is_train], speeds[~is_train]
    logger.info("%d speed steps x %d channel(s) at %.0f Hz (%s): extracting order features",
                speeds.size, len(channels), info["fs"],
                f"records start with a transient, first {transient_s:g} s kept apart"
                if starts_transient else "records are settled steady states")
    meas = order_features(measured, channels, transient_s)
    tick("measured order features")

    def update_from(start):
        return kept.step("update", start, lambda: _update_nominal(
            meas, train, channels, start, info, transient_s, settle_s, settings))

    update = None
    if settings.update_nominal:
        update = update_from(base)
        base = update.params
        tick("nominal model updating")
    model = SweepModel(base=base, fs=info["fs"], n_samples=info["n_samples"],
                       channels=tuple(channels), transient_s=transient_s, settle_s=settle_s,
                       lead_s=settings.warm_lead_s, step_factor=settings.step_factor)
    # the updated nominal model's features, simulated once: the model-form tolerance
    # reads them at every speed, the nuisance start at the training speeds
    nuis0 = np.array([v[3] for v in NUISANCE.values()])
    nominal_all = kept.step("features", [model, speeds, nuis0],
                            lambda: model.features(speeds, nuis0))
    spread, n_points = None, 0
    if update is not None and settings.update_spread:
        logger.info("the updated rotor's harmonics over its parameters' uncertainty")
        spread, n_points = kept.step(
            "spread", [model, speeds, update.nominal, update.theta, update.covariance],
            lambda: _prediction_spread(model, speeds, update, nominal_all, nuis0))
        tick("update uncertainty")
    meas = _with_model_tolerance(meas, nominal_all, update, spread)
    logger.info("calibrating the nominal model's nuisance scalars on %d training speeds",
                train.size)

    cal0, E0, cmp0 = kept.step("nuisance", [model, train, held], lambda: _nuisance_fit(
        model, meas, train, held, settings, nominal_all[nominal_all.speed.isin(train)]))
    _, cmp_all = kept.step("heldout", [model, speeds, [], cal0],
                           lambda: heldout_gap(model, meas, speeds, cal0, ()))
    tick("nuisance calibration")
    e0 = E0 / max(len(cmp0), 1)
    n_features = max(len(cmp0), 1)
    by_order = order_mean_z2(cmp0)
    over = orders_over_floor({k: v["mean_z2"] for k, v in by_order.items()}, settings)
    floors = order_floors(settings)
    doc = {
        "verdict": None, "ranking": [], "where": regions(cmp_all),
        "shrink": 0.0,
        "gap_before": {"heldout_excess": E0, "per_feature": e0,
                       "rms_gap_m": float(np.sqrt(np.mean(cmp0["gap"] ** 2))),
                       "by_order": {k: {**v, "floor_z2": floors.get(k), "over_floor": k in over}
                                    for k, v in by_order.items()}},
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
        "n_heldout_features": n_features,
    }
    if spread is not None:
        harm = (nominal_all["feature"] != "1x").to_numpy()
        doc["nominal_update"]["harmonic_spread"] = {
            "sigma_points": 2 * n_points,
            "median_m": float(np.median(spread[harm])),
            "max_m": float(np.max(spread[harm])),
            "rule": "each harmonic's and line's model-form tolerance is widened, in "
                    "quadrature, by its spread over the update's sigma points and the "
                    "rotor before the update"}
    if update is not None:
        doc["nominal_update"]["backward_whirl_1x"] = _whirl_summary(meas)
    result = GapDiagnosis(doc, front_end="time-series",
                          tables={"before": cmp0, "all": cmp_all}, base=base)
    # the verdict before any candidate: decide's own test, so the two cannot drift apart
    # (under the floor a candidate may still be named when attribute_below_floor is set)
    if (not exhaustive and not settings.attribute_below_floor
            and decide(e0, [], settings, n_features, over) == "no-gap"):
        doc["verdict"] = "no-gap"
        return result

    front = _SweepFrontEnd(model, meas, train, held, cmp0, settings, _candidate_start(cal0),
                           kept)
    logger.info("held-out gap %.3g per feature (no-gap floor %.3g)%s: fitting %d effect "
                "candidate(s)", e0, settings.no_gap_per_feature,
                "".join(f", {k} mean z2 {v:.3g} over its floor {floors[k]:.3g}"
                        for k, v in over.items()), len(candidates))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ranked = search(front, candidates, E0, cmp0, n_features, settings, tick)
    fronts = {None: front}
    if readings:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ranked, doc["rotor_readings"] = _in_other_readings(
                readings, ranked, fronts, nominal_base, update_from, model, meas,
                (train, held), settings, (E0, cmp0, n_features), tick, kept)
    choice = decide(e0, ranked, settings, n_features, over)
    if isinstance(choice, dict) and choice["_fit"].details.get("discrete_settings"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            choice, ranked = recheck_choice(_ByReading(fronts), choice, ranked, E0, cmp0,
                                            settings, n_features, e0, over)
        tick("verdict's other settings refitted from its fit")
    doc.update(conclude(choice, ranked, cmp0, doc["where"], settings, n_features))
    if isinstance(choice, dict):
        result.tables["after"] = choice["_cmp"]
        reading = choice.get("rotor_reading")
        if reading is not None:
            # the verdict's rotor is the reading it was fitted in, updated
            doc["rotor_reading"] = {"label": reading, "changes": readings[reading]}
            result.base = fronts[reading].model.base
    doc["ranking"] = public_ranking(ranked, settings, n_features)
    return result


def _nuisance_fit(model, meas, train, held, settings, nominal_train):
    """The nuisance-only model (no effect) calibrated on the training speeds, its
    unbalance phase started from the 1x phase against ``nominal_train`` (the model's
    own training-speed features): the fit, its held-out excess and comparison table."""
    m1 = meas[(meas.feature == "1x") & meas.speed.isin(train)]
    s1 = nominal_train.set_index(["speed", "window", "channel", "feature"]).reindex(
        pd.MultiIndex.from_frame(m1[["speed", "window", "channel", "feature"]]))
    dphi = float(np.angle(np.sum((m1.re.to_numpy() + 1j * m1.im.to_numpy())
                                 * np.conj(s1.re.to_numpy() + 1j * s1.im.to_numpy()))))
    start = np.array([1.0, dphi, 1.0, 1.0])
    cal0 = calibrate(model, meas, train, (), starts=[start], max_nfev=settings.max_nfev,
                     jacobian_refresh=settings.jacobian_refresh,
                     settled_sigma=settings.settled_sigma)
    E0, cmp0 = heldout_gap(model, meas, held, cal0, ())
    return cal0, E0, cmp0


def _heldout_or_diverged(model, meas, held, cal, classes):
    """:func:`heldout_gap` of a candidate's fit; a fit calibrated on the training speeds
    that is unstable at a held-out one is rejected: infinite excess, no table."""
    try:
        return heldout_gap(model, meas, held, cal, classes)
    except SimulationDivergenceError:
        return float("inf"), None


def _candidate_start(cal0):
    """Where candidates start: the nuisance-only fit's unbalance at nominal stiffness and
    damping scales. The nuisance-only fit absorbs what it can of an effect (a crack's
    loss of mean stiffness pulls the stiffness scale to 0.87, say) and a candidate
    started there stays in that basin; a rig's mismatch is a few per cent."""
    start = cal0.x.copy()
    start[[list(NUISANCE).index("stiffness_scale"),
           list(NUISANCE).index("damping_scale")]] = 1.0
    return start


def _in_other_readings(readings, ranked, fronts, nominal_base, update_from, model, meas,
                       split, settings, before, tick, kept):
    """The ranking with each other reading's fits added (:mod:`sknarx.gap.readings`):
    per reading, the nominal update started at it (``update_from``: the update from a
    rotor), its nuisance-only model (model error alone) and the search over the
    primary ranking's ``settings.reading_contenders`` best singles, all against the
    primary's features ``meas`` and tolerance (``before``: its held-out excess,
    comparison table and feature count; ``split``: training and held-out speeds).
    ``fronts`` gains each reading's front end by label; ``kept`` is the diagnosis's
    checkpoint. Returns the ranking and the document's ``rotor_readings`` entries."""
    train, held = split
    E0, cmp0, n_features = before
    names = reading_contenders(ranked, settings.reading_contenders)
    fits = [r["_fit"] for r in ranked]
    nuis0 = np.array([v[3] for v in NUISANCE.values()])
    entries = []
    for label, changes in readings.items():
        logger.info("rotor reading %r (%s): updating from it, then the nuisance-only model "
                    "and %s", label, ", ".join(f"{k} = {v:g}" for k, v in changes.items()),
                    ", ".join(names) or "no candidate")
        base = nominal_base.replace(**changes)
        update = None
        if settings.update_nominal:
            update = update_from(base)
            base = update.params
        model_r = dataclasses.replace(model, base=base)
        cal, E, cmp = kept.step("nuisance", [model_r, train, held], lambda m=model_r: _nuisance_fit(
            m, meas, train, held, settings, m.features(train, nuis0)))
        alone = CandidateFit(
            names=(), params={}, params_std={}, n_params=0, heldout_excess=E, cmp=cmp,
            details={"nuisance": cal.nuisance, "rotor_reading": label,
                     "evidence": table_evidence(cmp0, cmp)}, state=cal)
        front = _SweepFrontEnd(model_r, meas, train, held, cmp0, settings,
                               _candidate_start(cal), kept)
        fronts[label] = front
        found = search(front, names, E0, cmp0, n_features, settings) if names else []
        for f in (r["_fit"] for r in found):
            f.details["rotor_reading"] = label
        fits += [alone, *(r["_fit"] for r in found)]
        entries.append({"label": label, "changes": changes,
                        "heldout_gap_alone": E, "contenders": list(names),
                        "nominal_update": _update_summary(update)})
        tick(f"rotor reading {label!r}")
    return rank(fits, E0, cmp0), entries


class _ByReading(FrontEnd):
    """The front end of the reading each fit was made in (``rotor_reading``; None: the
    nominal rotor as given), for the verdict's recheck of its discrete settings."""

    def __init__(self, fronts):
        self.fronts = fronts

    def recheck_setting(self, fit):
        return self.fronts[fit.details.get("rotor_reading")].recheck_setting(fit)


def _plain_params(classes, effect_params):
    """Each effect's fitted parameters as plain numbers (projected effects, such as the
    per-probe runout vectors, through their ``to_dict``)."""
    return [c.from_params(p).to_dict() if getattr(c, "projected_orders", None) else p
            for c, p in zip(classes, effect_params, strict=True)]


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
