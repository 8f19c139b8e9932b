"""Calibrating a candidate effect (with nuisance parameters) to measured order features.

The model is the nominal rotor with four nuisance parameters a real rig always
needs -- unbalance magnitude scale and phase, a stiffness scale of the shaft
segments and a damping scale -- plus the candidate effect's own parameters.
Everything is fitted by ``scipy.optimize.least_squares`` (trust-region
reflective, bounds, finite differences) on the normalised order-domain
residuals of the training speeds, from several starts. Log-scaled parameters
are searched in log10.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.optimize import least_squares

from ..rotor import SimulationDivergenceError
from .gapmap import (
    compare,
    fast_residual,
    feature_layout,
    gap_statistic,
    model_tol,
    tolerances,
    whirl_layout,
    whirl_tol,
)
from .jacobian import SecantJacobian, SettledStop
from .sweep_model import NUISANCE, SweepModel

__all__ = ["Calibration", "calibrate", "heldout_gap"]

logger = logging.getLogger(__name__)


@dataclass
class Calibration:
    """The outcome of fitting one candidate (an effect class, a pair, or none)."""

    names: tuple  # canonical effect names, () for the nuisance-only model
    effect_params: list  # one dict per effect
    nuisance: dict
    std: dict  # 1-sigma of every fitted parameter (physical units)
    cost: float  # training sum of squared normalised residuals
    n_params: int
    success: bool
    x: np.ndarray = None

    def effects(self, classes):
        return [cls.from_params(p) for cls, p in zip(classes, self.effect_params,
                                                     strict=True)]


def _split_x(classes):
    """Layout of the optimisation vector: nuisance, then each effect's parameters, with
    each one's start in search space (an effect's stated ``start``, e.g. a crack's
    element stiffness at the model's; else a quarter into its range)."""
    lo, hi, log, names, x0 = [], [], [], [], []
    for n, (a, b, _sc, start) in NUISANCE.items():
        lo.append(a)
        hi.append(b)
        log.append(False)
        names.append(("nuisance", n))
        x0.append(start)
    for cls in classes:
        for n, (a, b, sc) in cls.bounds.items():
            is_log = sc == "log"
            to_x = np.log10 if is_log else float
            lo.append(to_x(a))
            hi.append(to_x(b))
            log.append(is_log)
            names.append((cls.name, n))
            given = getattr(cls, "start", {}).get(n)
            x0.append(to_x(given) if given is not None else lo[-1] + 0.25 * (hi[-1] - lo[-1]))
    return np.array(lo), np.array(hi), np.array(log), names, np.array(x0)


def _physical(x, log) -> np.ndarray:
    """Search-space values in physical units (the log-scaled ones from their log10)."""
    vals = np.array(x, dtype=float)
    vals[log] = 10.0 ** vals[log]
    return vals


def _decode(x, classes, log, combo=None):
    """Nuisance values and effect objects of a search vector; ``combo`` holds each
    class's discrete settings (e.g. a crack's station)."""
    vals = _physical(x, log)
    nuis = vals[: len(NUISANCE)]
    effects, i = [], len(NUISANCE)
    for c, cls in enumerate(classes):
        k = len(cls.bounds)
        eff = cls.from_vector(vals[i : i + k])
        if combo and combo[c]:
            eff = dataclasses.replace(eff, **combo[c])
        effects.append(eff)
        i += k
    return nuis, effects


def search_vector(effect) -> np.ndarray:
    """An effect's searched parameters as the calibration's vector holds them (log10 of
    the log-scaled ones): the inverse of :func:`_decode` for one effect."""
    return np.array([np.log10(getattr(effect, n)) if sc == "log" else getattr(effect, n)
                     for n, (_lo, _hi, sc) in type(effect).bounds.items()], dtype=float)


def effect_blocks(x, classes) -> list:
    """Each effect's slice of a calibration vector ``x`` (after the nuisances)."""
    widths = np.cumsum([len(c.bounds) for c in classes])[:-1]
    return np.split(np.asarray(x)[len(NUISANCE):], widths)


def _discrete_combos(classes, fixed):
    """Every combination of the classes' discrete settings still to search (those in
    ``fixed`` are held), as tuples of one dict per class."""
    fixed = list(fixed) if fixed is not None else [None] * len(classes)
    choices = []
    for cls, held in zip(classes, fixed, strict=True):
        options = getattr(cls, "discrete", {})
        if held is not None or not options:
            choices.append([held or {}])
        else:
            choices.append([dict(zip(options, v, strict=True))
                            for v in itertools.product(*options.values())])
    return list(itertools.product(*choices))


def discrete_settings(cal, i, cls) -> dict:
    """The discrete settings (e.g. the station) a calibration chose for class ``i``."""
    return {k: cal.effect_params[i][k] for k in getattr(cls, "discrete", {})}


def _probe_key(classes, combo, x):
    return (tuple(cls.name for cls in classes),
            tuple(tuple(sorted(c.items())) for c in combo), np.asarray(x).tobytes())


def _measured_arrays(meas_feats, index):
    """Measured vectors (m), standard errors, model-form tolerances (m) and the probe
    pairs' whirl layout (:func:`~sknarx.gap.gapmap.whirl_layout`) in the order of the
    simulated features' ``index``."""
    m = meas_feats.set_index(list(index.names)).reindex(index)
    if m["re"].isna().any():
        raise ValueError("measured and simulated features do not align")
    return (m["re"].to_numpy() + 1j * m["im"].to_numpy(), m["se"].to_numpy(), model_tol(m),
            whirl_layout(index, whirl_tol(m)))


def calibrate(model: SweepModel, meas_feats, speeds, classes=(), starts=None, max_nfev=20,
              diff_step=1e-3, n_probe=16, n_short=4, seed=0, probe_from=None,
              fixed=None, each_discrete=False, jacobian_refresh=None, probe_cache=None,
              settled_sigma=None, probes_per_parameter=None, rule=None):
    """Fit the nuisance parameters and the effects of ``classes`` on ``speeds``.

    The first ``starts`` entry (nuisance values, then effect values in search space)
    seeds the local least-squares run. With effects, ``n_probe`` settings of the
    effect parameters from a scrambled Sobol sequence are scored first and the
    ``n_short`` best of them get short local runs, and the best of those is run to
    convergence: the 2x phase of a crack, say, is periodic in its angle, and the
    cheapest probe, like local search alone, often sits in the wrong basin. Where the
    measured features carry a ``whirl_tol`` column, the probes and the short runs rank
    basins in the channel basis and the converged run is the whirl basis's (see
    :func:`~sknarx.gap.gapmap.compare`).
    ``probe_from`` (index into the search vector) restricts the probes to the
    trailing parameters -- a pair warm-started from its leading effect's fit probes
    only the partner. ``max_nfev=0`` returns the best probe without a local run.
    Discrete settings of an effect (``discrete``, e.g. a crack's station) are probed
    in every combination with the same Sobol points, and the local runs keep the
    combination of the probe they start from; ``fixed`` (one dict or None per class)
    holds some of them (a pair keeps its leading effect's station); the best short run
    of each combination runs to convergence. Returns the calibration of the lowest
    converged cost or, with ``each_discrete``, a list of each combination's: the
    training cost can barely tell stations apart where held-out speeds can, so the
    caller may choose among them as it chooses among candidates. Each local run and
    each discrete setting's probes continue the settled runs of their start when the
    model allows it (see
    :meth:`SweepModel.warmed`) instead of settling every evaluation from rest.
    ``jacobian_refresh`` (steps) makes the short runs' Jacobian a secant one, by forward
    differences only every so many steps and after a rejected step (see
    :class:`~sknarx.gap.jacobian.SecantJacobian`): they only rank basins; the converged
    runs difference theirs at every step (a secant Jacobian leaves the held-out choice
    of a crack's station to chance). None: forward differences
    throughout. ``probe_cache`` (a dict the caller keeps across calls on one model and
    one ``meas_feats``) remembers each probe's cost: probing the same points from the
    same start again (a pair's partner, then the pair) costs nothing.
    ``settled_sigma`` ends a converged run early once a step moved no parameter by
    more than that share of its standard error (see
    :class:`~sknarx.gap.jacobian.SettledStop`); None: ``max_nfev`` and scipy's
    tolerances alone. ``probes_per_parameter`` caps the probes at that many per probed
    parameter, rounded up to a power of two (a Sobol sequence's balanced sizes): a
    clearance's one parameter needs no 64-point grid; None: ``n_probe`` whatever the
    dimension. ``rule``: the :class:`~sknarx.gap.VerdictRule` whose tolerances the
    comparison applies (the default's when None).
    """
    from scipy.stats import qmc

    lo, hi, log, names, x_start = _split_x(classes)
    speeds = np.asarray(speeds, dtype=float)
    keys, _, _, _ = model.feature_arrays(speeds, np.array([1.0, 0.0, 1.0, 1.0]))
    index = pd.MultiIndex.from_tuples(keys, names=["speed", "window", "channel", "feature"])
    Mc, se_m, tol, whirl = _measured_arrays(meas_feats, index)
    order_k, speed_idx, group_idx = feature_layout(index)
    tols = tolerances(rule)
    size = 2 * len(keys)
    project = _projection(classes, keys, order_k, Mc, se_m)
    combos = _discrete_combos(classes, fixed)

    def simulated(xs, combo, sweep):
        """The features at each of the points ``xs``, simulated together (probes and a
        difference Jacobian's columns are independent points)."""
        points = [_decode(x, classes, log, combo) for x in xs]
        with np.errstate(all="ignore"):  # a diverging run's features overflow
            return sweep.feature_arrays_many(speeds, points)

    def compared(f, bases):
        """One point's residual in each of ``bases`` (the probe pairs' whirl layout,
        None for the channel basis), its features projected once."""
        try:
            if isinstance(f, Exception):
                raise f
            _, Sc, se_s, _ = f
            Sc, _, added = project(Sc, se_s)
            rs = [fast_residual(Mc, Sc, se_m=se_m, se_s=se_s, order_k=order_k,
                                speed_idx=speed_idx, group_idx=group_idx, model_tol=tol,
                                whirl=b, offset=added, **tols) for b in bases]
        except (SimulationDivergenceError, ValueError, FloatingPointError):
            rs = [np.full(size, 1e3) for _ in bases]
        return [r if np.all(np.isfinite(r)) else np.full(size, 1e3) for r in rs]

    def residuals(xs, combo=combos[0], sweep=model, basis=whirl):
        return [compared(f, (basis,))[0] for f in simulated(xs, combo, sweep)]

    def residual(x, combo=combos[0], sweep=model, basis=whirl):
        return residuals([x], combo, sweep, basis)[0]

    def warmed(x, combo):
        # every run of one local search continues the settled runs of its start: a
        # fraction of the settling per evaluation, and one smooth residual
        nuis, effects = _decode(x, classes, log, combo)
        try:
            with np.errstate(all="ignore"):
                return model.warmed(speeds, nuis, effects)
        except (SimulationDivergenceError, ValueError, FloatingPointError):
            return model

    def finish(x, std, cost, success, combo):
        """The calibration at ``x``, with the projected effects' closed-form values."""
        cal = _calibration(x, classes, log, std, cost, success, combo)
        if project.active:
            nuis, effects = _decode(x, classes, log, combo)
            with np.errstate(all="ignore"):
                _, Sc, se_s, _ = model.feature_arrays(speeds, nuis, effects)
            _, vectors, _ = project(Sc, se_s)
            for i, cls in enumerate(classes):
                if getattr(cls, "projected_orders", None):
                    cal.effect_params[i] = {"vectors": cls.from_projection(vectors).vectors}
            cal.n_params += project.n_values
        return cal

    def start_vector(start):
        x0 = x_start.copy()
        if start is not None:
            x0[: len(start)] = start[: len(x0)]
        return np.clip(x0, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))

    x0s = [(start_vector(s), combos[0]) for s in (starts or [None])]
    # basins are probed and ranked in the channel basis and converged in the whirl
    # basis: there a disk's backward whirl is trusted only to the nominal model's own,
    # so a probe leads by where its ellipse happens to fall, and a rub's short runs
    # from such probes stay in a basin that the whirl basis itself scores worse than
    # the one the channel basis leads to. A probe's cost is kept in both (one
    # simulation); probes alone (max_nfev 0, a partner's score) are the whirl basis's,
    # as a converged fit's cost is.
    bases = (whirl,) if whirl is None else (whirl, None)
    ranked_by = 0 if max_nfev == 0 or whirl is None else 1  # index into bases
    j0 = len(NUISANCE) if probe_from is None else probe_from
    if classes and n_probe and j0 < len(lo):
        base = x0s[0][0]
        j = slice(j0, len(lo))
        dim = len(lo) - j0
        if probes_per_parameter:
            n_probe = min(n_probe, 2 ** math.ceil(math.log2(probes_per_parameter * dim)))
        unit = qmc.Sobol(dim, scramble=True, seed=seed).random(n_probe)
        probes = []
        for combo in combos:
            points = [*(np.concatenate([base[:j0], lo[j] + u * (hi[j] - lo[j])])
                        for u in unit), base]
            # the same points from the same start (a partner's probes on top of a lead,
            # then the pair's own) cost nothing the second time
            keys = [_probe_key(classes, combo, x) for x in points]
            if probe_cache is None or any(k not in probe_cache for k in keys):
                sweep = warmed(base, combo)
                for k, x, f in zip(keys, points, simulated(points, combo, sweep),
                                   strict=True):
                    costs = tuple(float(np.sum(r ** 2)) for r in compared(f, bases))
                    if probe_cache is not None:
                        probe_cache[k] = costs
                    probes.append((costs[ranked_by], x, combo))
            else:
                probes += [(probe_cache[k][ranked_by], x, combo)
                           for k, x in zip(keys, points, strict=True)]
        probes.sort(key=lambda p: p[0])
        # each discrete setting gets its own leading starts: a wrong station's probes
        # can all undercut the right one's before any local run (seen on a crack at A-O1
        # whose O2-B probes led, while A-O1's fourth-best converged to 1/12 of their cost)
        x0s = [(x, combo) for combo in combos
               for _, x, _ in [p for p in probes if p[2] is combo][:n_short]]
        if max_nfev == 0:  # probes only: the best probe, unpolished (no uncertainty)
            cal = finish(probes[0][1], {}, probes[0][0], False, probes[0][2])
            return [cal] if each_discrete else cal
    elif len(combos) > 1:  # no probes: each discrete setting scored at the start
        x0 = x0s[0][0]
        x0s = [min(((x0, c) for c in combos),
                   key=lambda xc: float(np.sum(residual(*xc) ** 2)))]
    if max_nfev == 0:  # nothing to probe (e.g. a partner solved in closed form): the start
        x0, combo = x0s[0]
        cal = finish(x0, {}, float(np.sum(residual(x0, combo) ** 2)), False, combo)
        return [cal] if each_discrete else cal

    def local(x0, nfev, combo, refresh=None, settled=None, basis=whirl):
        sweep = warmed(x0, combo)
        if refresh is None and settled is None:
            return least_squares(residual, x0, bounds=(lo, hi), method="trf",
                                 x_scale=hi - lo, diff_step=diff_step, max_nfev=nfev,
                                 args=(combo, sweep, basis))
        # refresh 1: forward differences at every step, kept for the stop rule
        jac = SecantJacobian(lambda x: residual(x, combo, sweep, basis), lo, hi,
                             diff_step, refresh or 1,
                             many=lambda xs: residuals(xs, combo, sweep, basis))
        stop = SettledStop(jac, settled) if settled is not None else None
        res = least_squares(jac.residual, x0, jac=jac, bounds=(lo, hi), method="trf",
                            x_scale=hi - lo, max_nfev=nfev, callback=stop)
        if stop is not None and stop.stopped:
            res.success = True  # settled within its uncertainty: converged
        return res

    if len(x0s) > 1:
        # the cheapest probe is often in the wrong basin of a periodic parameter: a short
        # run from each of the leading starts, then the best of them runs to the end --
        # the best of each discrete setting: three iterations do not tell the stations
        # apart
        short = [(local(x0, max(3, max_nfev // 4), combo, jacobian_refresh,
                        basis=None), combo)  # the channel basis ranks basins (above)
                 for x0, combo in x0s]
        best = [(min(runs, key=lambda r: r.cost), c) for c in combos
                if (runs := [r for r, rc in short if rc is c])]
        if len(best) > 1:
            logger.debug("discrete settings, best short-run cost: %s",
                         ", ".join(f"{c}: {2 * r.cost:.4g}" for r, c in best))
        x0s = [(r.x, c) for r, c in best]
    finals = [(local(x0, max_nfev, combo, settled=settled_sigma), combo)
              for x0, combo in x0s]
    if len(finals) > 1:
        logger.debug("discrete settings, converged cost: %s",
                     ", ".join(f"{c}: {2 * r.cost:.4g}" for r, c in finals))
    cals = [finish(r.x, _std(r, log, names), float(2 * r.cost), bool(r.success), c)
            for r, c in finals]
    return cals if each_discrete else min(cals, key=lambda cal: cal.cost)


def _projection(classes, keys, order_k, Mc, se_m):
    """Closed-form fit of the effects whose parameters are constant per-channel order
    vectors (``projected_orders``, e.g. probe runout): for given other parameters, the
    weighted mean over the calibration speeds of measured minus simulated, per channel
    and order, is the least-squares vector (variable projection)."""
    orders = sorted({k for cls in classes for k in getattr(cls, "projected_orders", ())})
    chans = np.array([k[2] for k in keys])
    groups = [(ch, k, np.flatnonzero((chans == ch) & (order_k == k)))
              for ch in dict.fromkeys(chans.tolist()) for k in orders]
    groups = [g for g in groups if g[2].size]

    def project(Sc, se_s):
        """``(Sc + vectors, vectors, added)``: ``added`` the vector each feature got
        (None without projected effects), for the comparison's tolerances to leave out."""
        vectors = {}
        if not groups:
            return Sc, vectors, None
        Sc = Sc.copy()
        added = np.zeros(Sc.size, complex)
        w = 1.0 / np.maximum(se_m**2 + se_s**2, 1e-300)
        for ch, k, idx in groups:
            v = complex(np.sum(w[idx] * (Mc[idx] - Sc[idx])) / np.sum(w[idx]))
            Sc[idx] += v
            added[idx] = v
            vectors.setdefault(ch, {})[k] = v
        return Sc, vectors, added

    project.active = bool(groups)
    project.n_values = 2 * len(groups)  # real and imaginary part of each vector
    return project


def _calibration(x, classes, log, std, cost, success, combo=None):
    nuis, effects = _decode(x, classes, log, combo)
    return Calibration(
        names=tuple(c.name for c in classes),
        effect_params=[{n: getattr(e, n) for n in [*type(e).bounds,
                                                   *getattr(type(e), "discrete", {})]}
                       for e in effects],
        nuisance=dict(zip(NUISANCE, map(float, nuis), strict=True)),
        std=std, cost=cost, n_params=len(x), success=success, x=x)


def _std(res, log, names):
    J = res.jac
    m, p = J.shape
    dof = max(m - p, 1)
    s2 = 2 * res.cost / dof
    try:
        cov = np.linalg.pinv(J.T @ J) * s2
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        sd = np.full(p, np.nan)
    vals = _physical(res.x, log)
    # log-space sigma -> physical sigma (delta method)
    sd = np.where(log, vals * np.log(10.0) * sd, sd)
    return {f"{a}.{b}": float(v) for (a, b), v in zip(names, sd, strict=True)}


def heldout_gap(model: SweepModel, meas_feats, speeds, cal: Calibration, classes,
                rule=None):
    """Excess gap of a calibrated model on held-out speeds, with its comparison table
    (the tolerances ``rule``'s, the default's when None)."""
    nuis = np.array(list(cal.nuisance.values()))
    effects = cal.effects(classes)
    with np.errstate(all="ignore"):
        sim = model.features(speeds, nuis, effects)
    # a fitted runout's vectors are the probes', not the rotor's: the comparison's
    # tolerances leave them out as the calibration's did
    vectors = {}
    for e in effects:
        for ch, by_order in getattr(e, "order_vectors", dict)().items():
            vectors.setdefault(ch, {}).update(by_order)
    cmp = compare(meas_feats[meas_feats.speed.isin(speeds)], sim, rule, probe_vectors=vectors)
    return gap_statistic(cmp), cmp
