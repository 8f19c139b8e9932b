"""The time-series front end: stepped-speed sweeps against the nonlinear simulator.

1. The speed steps alternate between training and held-out (the highest for training).
2. The nominal rotor's linear parameters are updated on the training steps' steady 1x
   (:mod:`sknarx.gap.updating`); each feature's model-form tolerance carries what the
   update could not follow or left uncertain (:mod:`sknarx.gap.tolerance`). The four
   nuisance scalars are calibrated; the held-out excess left is the gap *before*, and
   the no-gap floor is what the sweep's measured noise alone would leave
   (:mod:`sknarx.gap.floor`).
3. Every candidate effect is calibrated with the nuisances on the training steps and
   judged on the held-out ones; pairs, the lead's continuation, linear forms and the
   verdict's discrete settings follow (:mod:`sknarx.gap.search`).
4. The verdict rule decides (:class:`~sknarx.gap.VerdictRule`).
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
import pandas as pd

from .._checkpoint import Checkpoint, NoCheckpoint
from .._progress import phase
from ..orders import TRANSIENT_RATIO, free_response_decay, is_nonsync, order_features
from ..rotor import EFFECTS, RotorParameters
from .budget import SearchBudget
from .calibration import calibrate, heldout_gap
from .candidate import Candidate
from .document import ranking_entries, verdict_entries, with_passes
from .evidence import alternating_split, table_evidence
from .floor import sweep_noise_floor
from .gapmap import regions
from .passes import compare_passes
from .readings import check_readings, reading_contenders
from .result import GapDiagnosis
from .rule import VerdictRule
from .search import rank, recheck_setting, search
from .sweep_front import SweepFrontEnd
from .sweep_model import NUISANCE, SweepModel
from .tolerance import prediction_spread, update_summary, whirl_summary, with_model_tolerance
from .updating import linear_1x, update_nominal_model

__all__ = ["LIBRARY", "diagnose"]

logger = logging.getLogger(__name__)

#: Candidate effects searched by default (measurement noise is characterised, not
#: searched: every measurement has some).
LIBRARY = ("rub", "misalignment", "crack", "looseness", "clearance", "anisotropy", "runout",
           "speed-fluctuation")
#: start of the nuisance scalars: nominal unbalance, phase, stiffness and damping
NUISANCE_START = np.array([v[3] for v in NUISANCE.values()])


def _steady_1x(meas, speeds, channels):
    """Measured steady-window 1x vectors (m) and standard errors, (speeds, channels)."""
    m = meas[(meas.feature == "1x") & (meas.window == "steady")].set_index(
        ["speed", "channel"])
    m = m.reindex(pd.MultiIndex.from_product([list(speeds), list(channels)]))
    shape = (len(speeds), len(channels))
    z = (m["re"].to_numpy() + 1j * m["im"].to_numpy()).reshape(shape)
    return z, m["se"].to_numpy().reshape(shape)


#: samples the steady window needs at least for its order features (as
#: :func:`sknarx.orders.record_features`) and whole revolutions of the slowest speed
MIN_STEADY_SAMPLES, MIN_STEADY_REVOLUTIONS = 32, 4


def _check_steady_window(info, transient_s):
    """A user error when records that start with a transient leave no steady window."""
    fs, n = info["fs"], info["n_samples"]
    w_min = float(min(info["speeds"]))
    need = transient_s + max(MIN_STEADY_SAMPLES / fs, MIN_STEADY_REVOLUTIONS * 2 * np.pi / w_min)
    if n / fs < need:
        raise ValueError(
            f"measured data: each speed step's record is {n / fs:.3g} s long and starts "
            f"with a transient (its first {transient_s:g} s are kept apart), which leaves "
            f"too little steady record; record at least {need:.2g} s per speed step "
            f"({MIN_STEADY_REVOLUTIONS} revolutions at {w_min:g} rad/s after the transient).")


def _update_nominal(meas, train, channels, base, info, transient_s, settle_s, budget):
    """Nominal model updating on the training speeds' steady 1x, simulated over exactly
    the steady window the features were taken from. Each probe's constant vector is
    left out of it: a vector the same at every speed is runout's to explain."""
    z, se = _steady_1x(meas, train, channels)
    skip = int(round(transient_s * info["fs"]))
    # where the keyphasor sits on the shaft is arbitrary: the unbalance angle starts from
    # the measured 1x phase against the linearised nominal rotor's, weighted by amplitude
    f0 = linear_1x(base, train, channels)
    dphi = float(np.angle(np.sum(z * np.conj(f0))))
    base = base.replace(unbalance_phase=float(np.angle(np.exp(1j * (base.unbalance_phase
                                                                    + dphi)))))
    logger.info("updating the nominal rotor's parameters on the steady 1x of %d training "
                "speeds", len(train))
    return update_nominal_model(
        z, np.maximum(se, 1e-12), train, channels, base=base,
        max_nfev=budget.update_max_nfev, remove_constant=True,
        nonlinear_kwargs={"fs": info["fs"], "n_samples": info["n_samples"] - skip,
                          "settle": settle_s + transient_s,
                          "step_factor": budget.step_factor, "solver": budget.solver})


def _in_phase(desc, compute):
    """``compute`` run under a progress bar named ``desc`` (its elapsed time and
    simulations move while it runs)."""
    def run():
        with phase(desc):
            return compute()

    return run


def _nuisance_fit(model, meas, train, held, rule, budget, nominal_train):
    """The nuisance-only model calibrated on the training speeds (its unbalance phase
    started from the 1x phase against its own features ``nominal_train``), its held-out
    excess and table, and the no-gap floor of its held-out comparison."""
    key = ["speed", "window", "channel", "feature"]
    m1 = meas[(meas.feature == "1x") & meas.speed.isin(train)]
    s1 = nominal_train.set_index(key).reindex(pd.MultiIndex.from_frame(m1[key]))
    dphi = float(np.angle(np.sum((m1.re.to_numpy() + 1j * m1.im.to_numpy())
                                 * np.conj(s1.re.to_numpy() + 1j * s1.im.to_numpy()))))
    cal0 = calibrate(model, meas, train, (), starts=[np.array([1.0, dphi, 1.0, 1.0])],
                     max_nfev=budget.max_nfev, jacobian_refresh=budget.jacobian_refresh,
                     settled_sigma=budget.settled_sigma, rule=rule)
    E0, cmp0 = heldout_gap(model, meas, held, cal0, (), rule)
    sim = model.features(held, np.array(list(cal0.nuisance.values())))
    floor = sweep_noise_floor(meas[meas.speed.isin(held)], sim, rule, budget.n_bootstrap,
                              budget.random_state)
    return cal0, E0, cmp0, floor


def _candidate_start(cal0):
    """Where candidates start: the nuisance-only fit's unbalance at nominal stiffness and
    damping scales (that fit absorbs what it can of an effect, and a candidate started
    there stays in its basin; a rig's mismatch is a few per cent)."""
    start = cal0.x.copy()
    start[[list(NUISANCE).index("stiffness_scale"),
           list(NUISANCE).index("damping_scale")]] = 1.0
    return start


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


def _by_order(cmp0) -> dict:
    """Each shaft order's mean z2 over its held-out features, with their number."""
    rows = cmp0[~cmp0["feature"].map(is_nonsync)].groupby("feature")["z2"]
    return {k: {"mean_z2": float(m), "n": int(n)}
            for k, m, n in zip(rows.mean().index, rows.mean(), rows.size(), strict=True)}


def diagnose(measured: pd.DataFrame, base: RotorParameters | None = None, channels=None,
             candidates=LIBRARY, rule: VerdictRule | None = None,
             budget: SearchBudget | None = None, update: bool = True,
             transient_s: float = 0.5, readings=None,
             second_pass: pd.DataFrame | None = None, checkpoint=None, n_jobs=None,
             progress=None) -> GapDiagnosis:
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
    rule : VerdictRule, optional
        The values that decide the verdict and the comparison's tolerances.
    budget : SearchBudget, optional
        How hard the search tries.
    update : bool, default=True
        Update the nominal rotor's linear parameters on the training speeds' steady 1x
        before any effect is blamed; False fits the four nuisance scalars only.
    transient_s : float, default=0.5
        Length (s) of the window kept apart at the start of records that start with a
        transient (read from the records); settled records have none.
    readings : mapping, optional
        Alternative readings of the nominal rotor, ``{label: {parameter: value}}``
        (:class:`~sknarx.rotor.RotorParameters` fields, SI): model-form choices the
        rotor's description leaves open, each a discrete setting of the rotor the
        held-out speeds choose (:mod:`sknarx.gap.readings`).
    second_pass : DataFrame, optional
        A second pass of the same sweep (e.g. the coast-down), compared with
        ``measured`` model-free first (:func:`sknarx.gap.compare_passes`): where they
        differ beyond their noise the rotor changed between them and the verdict is
        ``unexplained`` (:func:`sknarx.gap.document.with_passes`).
    checkpoint : str or Path, optional
        A directory that keeps each finished step, so that a stopped diagnosis resumes
        where it stopped with the same result (:mod:`sknarx._checkpoint`). None:
        nothing is kept.
    n_jobs : int, optional
        Candidate fits run in parallel through joblib (None: one at a time, or as a
        ``joblib.parallel_config`` context says; a dask backend runs them on its
        cluster). Each fit runs its speed steps on threads.
    progress : callable, optional
        Called with a short message after each phase (default: the package logger).

    Returns
    -------
    GapDiagnosis
        Reads like ``diagnosis.json`` (``verdict``, ``ranking``, ``where``, ``shrink``,
        ...: ``docs/gap.md``); ``tables`` holds the comparison tables, ``base`` the
        updated nominal rotor, ``verdict`` the rule's typed answer. The caller writes
        the report (:func:`sknarx.gap.report.write_gap_outputs`).

    Examples
    --------
    >>> from sknarx.gap import diagnose
    >>> from sknarx.testing import make_trial
    >>> measured, truth = make_trial("none", seed=0)  # doctest: +SKIP
    >>> diagnose(measured)["verdict"]  # doctest: +SKIP
    'no-gap'
    """
    from threadpoolctl import threadpool_limits

    rule = rule or VerdictRule()
    budget = budget or SearchBudget()
    # each evaluation runs its speeds on threads; a BLAS that threads the features'
    # small solves as well fights them for the cores
    with threadpool_limits(limits=1, user_api="blas"):
        passes = None
        if second_pass is not None:
            passes = compare_passes(measured, second_pass, channels, rule, transient_s)
            logger.info("second pass against the first: a normal deviate of %.3g beyond "
                        "the dead band (floor %.3g): %s", passes.statistic, passes.floor,
                        "the rotor changed between the passes" if passes.changed
                        else "the passes agree")
        readings = check_readings(readings, base)
        kept = NoCheckpoint()
        if checkpoint is not None:
            kept = Checkpoint(checkpoint, {
                "measured": measured, "base": base, "channels": channels,
                "candidates": list(candidates), "rule": rule, "budget": budget,
                "update": update, "transient_s": transient_s, "readings": readings})
        run = _Run(measured, base, channels, candidates, rule, budget, update, transient_s,
                   readings, kept, n_jobs, progress or logger.info)
        result = run.diagnose()
        if checkpoint is not None:
            logger.info("checkpoint %s: %d step(s) read back, %d computed", checkpoint,
                        kept.reused, kept.computed)
        return with_passes(result, passes)


class _Run:
    """One diagnosis's state as its phases build it (see :func:`diagnose`)."""

    def __init__(self, measured, base, channels, candidates, rule, budget, update,
                 transient_s, readings, kept, n_jobs, tick):
        from .measured import check_measured

        unknown = [c for c in candidates if c not in EFFECTS]
        if unknown:
            raise ValueError(f"Unknown effect(s) {unknown}; the library has "
                             f"{', '.join(LIBRARY)}.")
        self.candidates, self.rule, self.budget = tuple(candidates), rule, budget
        self.update, self.readings, self.kept = update, readings, kept
        self.n_jobs, self.tick = n_jobs, tick
        self.measured, self.info = check_measured(measured, channels)
        self.channels = self.info["channels"]
        self.nominal_base = base or RotorParameters()
        # transient or settled is read from the records, not assumed from their time
        self.decay = free_response_decay(self.measured, self.channels)
        self.starts_transient = bool(self.decay["transient"].median() >= 0.5)
        self.transient_s = transient_s if self.starts_transient else 0.0
        self.settle_s = 0.0 if self.starts_transient else budget.settle_s
        _check_steady_window(self.info, self.transient_s)
        self.speeds = np.array(self.info["speeds"])
        is_train = alternating_split(self.speeds.size)
        self.train, self.held = self.speeds[is_train], self.speeds[~is_train]

    def _updated(self, start):
        """The nominal update started at rotor ``start`` (None without updating)."""
        if not self.update:
            return None
        return self.kept.step("update", start, _in_phase("nominal model updating",
                              lambda: _update_nominal(
                                  self.meas, self.train, self.channels, start, self.info,
                                  self.transient_s, self.settle_s, self.budget)))

    def _nuisance(self, model, nominal=None):
        """:func:`_nuisance_fit` of ``model`` (``nominal``: its features at every speed,
        simulated here when None)."""
        def compute():
            own = model.features(self.train, NUISANCE_START) if nominal is None else \
                nominal[nominal.speed.isin(self.train)]
            return _nuisance_fit(model, self.meas, self.train, self.held, self.rule,
                                 self.budget, own)

        return self.kept.step("nuisance", [model, self.train, self.held, self.rule,
                                           self.budget.n_bootstrap,
                                           self.budget.random_state],
                              _in_phase("nuisance calibration", compute))

    def diagnose(self) -> GapDiagnosis:
        info, rule, budget = self.info, self.rule, self.budget
        logger.info("%d speed steps x %d channel(s) at %.0f Hz (%s): extracting order "
                    "features", self.speeds.size, len(self.channels), info["fs"],
                    f"records start with a transient, first {self.transient_s:g} s kept "
                    "apart" if self.starts_transient else "records are settled steady states")
        self.meas = order_features(self.measured, self.channels, self.transient_s)
        self.tick("measured order features")
        update = self._updated(self.nominal_base)
        base = update.params if update is not None else self.nominal_base
        if update is not None:
            self.tick("nominal model updating")
        self.model = SweepModel(base=base, fs=info["fs"], n_samples=info["n_samples"],
                                channels=tuple(self.channels), transient_s=self.transient_s,
                                settle_s=self.settle_s, lead_s=budget.warm_lead_s,
                                step_factor=budget.step_factor, solver=budget.solver)
        self.nominal_all = self.kept.step(
            "features", [self.model, self.speeds, NUISANCE_START],
            _in_phase("the updated rotor at every speed",
                      lambda: self.model.features(self.speeds, NUISANCE_START)))
        spread, n_points = None, 0
        if update is not None:
            logger.info("the updated rotor's harmonics over its parameters' uncertainty")
            spread, n_points = self.kept.step(
                "spread", [self.model, self.speeds, update.nominal, update.theta,
                           update.covariance],
                lambda: prediction_spread(self.model, self.speeds, update, self.nominal_all,
                                          NUISANCE_START))
            self.tick("update uncertainty")
        self.meas = with_model_tolerance(self.meas, self.nominal_all, update, rule.rtol, spread)
        logger.info("calibrating the nominal model's nuisance scalars on %d training speeds",
                    self.train.size)
        cal0, E0, cmp0, floor = self._nuisance(self.model, self.nominal_all)
        _, cmp_all = self.kept.step(
            "heldout", [self.model, self.speeds, [], cal0, rule],
            _in_phase("the calibrated rotor at every speed",
                      lambda: heldout_gap(self.model, self.meas, self.speeds, cal0, (), rule)))
        self.tick("nuisance calibration")
        n = max(len(cmp0), 1)
        e0 = E0 / n
        doc = {
            "verdict": None, "ranking": [], "where": regions(cmp_all, rule.region_z2),
            "shrink": 0.0,
            "gap_before": {"heldout_excess": E0, "per_feature": e0,
                           "rms_gap_m": float(np.sqrt(np.mean(cmp0["gap"] ** 2))),
                           "floor": floor.to_dict(), "by_order": _by_order(cmp0)},
            "nuisance": {"calibrated": cal0.nuisance, "std": cal0.std},
            "noise": _noise_summary(self.meas),
            "split": {"train_speeds": self.train.tolist(),
                      "heldout_speeds": self.held.tolist()},
            "sampling": {"fs_hz": info["fs"], "samples_per_step": info["n_samples"]},
            "records": {
                "starts_with_transient": self.starts_transient,
                "transient_window_s": self.transient_s,
                "simulation_settle_s": self.model.settle_s,
                "decay_ratio": self.decay["ratio"].tolist(),
                "decayed_s": self.decay["decayed_s"].tolist(),
                "rule": f"first-eighth residual RMS over the second half's > "
                        f"{TRANSIENT_RATIO:g} on most steps: the records start with a "
                        "transient"},
            "channels": list(self.channels),
            "settings": {"rule": rule.to_dict(), "budget": budget.to_dict(),
                         "update": self.update, "transient_s": self.transient_s},
            "nominal_update": update_summary(update),
            "n_heldout_features": n,
        }
        if spread is not None:
            harm = (self.nominal_all["feature"] != "1x").to_numpy()
            doc["nominal_update"]["harmonic_spread"] = {
                "sigma_points": 2 * n_points, "median_m": float(np.median(spread[harm])),
                "max_m": float(np.max(spread[harm])),
                "rule": "each harmonic's and line's model-form tolerance is widened, in "
                        "quadrature, by its spread over the update's sigma points and the "
                        "rotor before the update"}
            doc["nominal_update"]["backward_whirl_1x"] = whirl_summary(self.meas)
        result = GapDiagnosis(doc, front_end="time-series",
                              tables={"before": cmp0, "all": cmp_all}, base=base)
        logger.info("held-out gap %.3g per feature (its noise floor %.3g): fitting %d effect "
                    "candidate(s)", e0, floor.floor, len(self.candidates))
        front = SweepFrontEnd(self.model, self.meas, self.train, self.held, cmp0, rule,
                              budget, _candidate_start(cal0), self.kept)
        ranked = search(front, self.candidates, E0, cmp0, n, rule, budget, self.n_jobs,
                        self.tick)
        fronts = {None: front}
        if self.readings:
            ranked, doc["rotor_readings"] = self._in_other_readings(ranked, fronts, E0, cmp0)
        verdict = rule.decide(e0, ranked, floor, n)
        named = verdict.named
        if named is not None and named.details.get("discrete_settings"):
            verdict, ranked = recheck_setting(
                fronts[named.details.get("rotor_reading")], verdict, ranked, E0, cmp0, rule,
                n, floor)
            self.tick("verdict's other settings refitted from its fit")
        doc.update(verdict_entries(verdict, ranked, cmp0, doc["where"], rule, budget, n))
        named = verdict.named
        if named is not None:
            result.tables["after"] = named.cmp
            label = named.details.get("rotor_reading")
            if label is not None:
                # the verdict's rotor is the reading it was fitted in, updated
                doc["rotor_reading"] = {"label": label, "changes": self.readings[label]}
                result.base = fronts[label].model.base
        doc["ranking"] = ranking_entries(ranked, floor, n)
        result.verdict = verdict
        return result

    def _in_other_readings(self, ranked, fronts, E0, cmp0):
        """The ranking with each other reading's fits added: per reading, the nominal
        update started at it, its nuisance-only model (model error alone) and the
        search over the rotor as given's best singles, all against the same features
        and tolerances. ``fronts`` gains each reading's front end by label."""
        n = max(len(cmp0), 1)
        names = reading_contenders(ranked, self.budget.reading_contenders)
        fits, entries = list(ranked), []
        for label, changes in self.readings.items():
            logger.info("rotor reading %r (%s): updating from it, then the nuisance-only "
                        "model and %s", label,
                        ", ".join(f"{k} = {v:g}" for k, v in changes.items()),
                        ", ".join(names) or "no candidate")
            update = self._updated(self.nominal_base.replace(**changes))
            base = update.params if update is not None else \
                self.nominal_base.replace(**changes)
            model = dataclasses.replace(self.model, base=base)
            cal, E, cmp, _ = self._nuisance(model)
            alone = Candidate(effects=(), params={}, params_std={}, n_params=0,
                              heldout_after=E, cmp=cmp,
                              details={"nuisance": cal.nuisance, "rotor_reading": label,
                                       "evidence": table_evidence(cmp0, cmp)}, state=cal)
            front = SweepFrontEnd(model, self.meas, self.train, self.held, cmp0, self.rule,
                                  self.budget, _candidate_start(cal), self.kept)
            fronts[label] = front
            found = search(front, names, E0, cmp0, n, self.rule, self.budget,
                           self.n_jobs) if names else []
            for f in found:
                f.details["rotor_reading"] = label
            fits += [alone, *found]
            entries.append({"label": label, "changes": changes, "heldout_gap_alone": E,
                            "contenders": list(names),
                            "nominal_update": update_summary(update)})
            self.tick(f"rotor reading {label!r}")
        return rank(fits, E0, cmp0), entries
