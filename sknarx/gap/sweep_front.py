"""The time-series front end's fits: the nonlinear simulator, with the nuisance scalars
and a candidate's effects, calibrated on the training speeds' order features."""

from __future__ import annotations

import numpy as np

from ..rotor import EFFECTS, SimulationDivergenceError
from .calibration import calibrate, discrete_settings, effect_blocks, heldout_gap, search_vector
from .candidate import Candidate
from .evidence import setting_support, table_evidence
from .search import FrontEnd, run_parallel
from .sweep_model import NUISANCE

__all__ = ["SweepFrontEnd", "setting_key"]

#: a candidate's entries about its discrete settings, kept with it through refits
SETTING_KEYS = ("discrete_settings", "setting_decided")


def setting_key(setting) -> tuple:
    """A discrete setting (``{effect: {name: value}}``) as a dict key."""
    return tuple((n, tuple(sorted(d.items()))) for n, d in sorted(setting.items()))


def _plain_params(classes, effect_params):
    """Each effect's fitted parameters as plain numbers (projected effects, such as the
    per-probe runout vectors, through their ``to_dict``)."""
    return [c.from_params(p).to_dict() if getattr(c, "projected_orders", None) else p
            for c, p in zip(classes, effect_params, strict=True)]


def setting_rows(fits, rule, budget) -> dict:
    """A candidate's discrete-setting entries from ``(setting, fit, refitted)`` per
    setting, the chosen one first: each setting's held-out excess and training cost and,
    for the others, how often the held-out speeds prefer the chosen one; the setting is
    *decided* where every such share reaches the rule's ``setting_support``."""
    best = fits[0][1]
    rows = [{"setting": setting, "heldout_gap_after": f.heldout_after,
             "training_cost": f.state.cost,
             **({"from_chosen_fit": True} if refitted else {}),
             **({} if f is best or best.cmp is None else {"chosen_preferred_share":
                 setting_support(best.cmp, f.cmp, budget.n_bootstrap, budget.random_state)})}
            for setting, f, refitted in fits]
    shares = [r["chosen_preferred_share"] for r in rows[1:] if "chosen_preferred_share" in r]
    return {"discrete_settings": rows,
            "setting_decided": bool(shares) and min(shares) >= rule.setting_support}


class SweepFrontEnd(FrontEnd):
    """Fits of the effect library on the nonlinear simulator (see
    :func:`sknarx.gap.diagnose`): ``model`` the updated nominal rotor's
    :class:`~sknarx.gap.sweep_model.SweepModel`, ``meas`` the measured features with
    their tolerances, ``train``/``held`` the speeds, ``cmp0`` the held-out table before
    any candidate, ``nuis_start`` where candidates start, ``checkpoint`` the steps a
    rerun reads back."""

    def __init__(self, model, meas, train, held, cmp0, rule, budget, nuis_start, checkpoint):
        self.model, self.meas, self.train, self.held = model, meas, train, held
        self.cmp0, self.rule, self.budget, self.nuis_start = cmp0, rule, budget, nuis_start
        self.checkpoint = checkpoint
        self._lead_x = None
        # each probe's cost by effects, discrete settings and point (saves work only)
        self._probe_costs = {}
        # each candidate's fit per discrete setting, best first
        self._setting_fits = {}

    def absorb(self, fit):
        if fit.settings_tried:
            self._setting_fits[fit.effects] = fit.settings_tried

    def _heldout(self, cal, classes):
        try:
            return heldout_gap(self.model, self.meas, self.held, cal, classes, self.rule)
        except SimulationDivergenceError:  # stable in training, unstable held out
            return float("inf"), None

    def _result(self, names, cal, classes=None):
        """The candidate of calibration ``cal``; with ``classes``, those it calibrated,
        where a class not named in ``names`` is a member's linear form (model error)."""
        classes = list(classes) if classes is not None else [EFFECTS[n] for n in names]
        E, cmp = self.checkpoint.step("heldout", [self.model, self.held, classes, cal,
                                                  self.rule], lambda: self._heldout(cal, classes))
        plain = _plain_params(classes, cal.effect_params)
        params = [p for c, p in zip(classes, plain, strict=True) if c.name in names]
        error = {c.name: p for c, p in zip(classes, plain, strict=True) if c.name not in names}
        details = {"nuisance": cal.nuisance,
                   "evidence": table_evidence(self.cmp0, cmp) if cmp is not None else
                   ["the calibrated model diverges at a held-out speed"],
                   "signature": [EFFECTS[n].signature for n in names]}
        if error:
            details["model_error"] = error
        return Candidate(
            effects=tuple(names), params=params[0] if len(names) == 1 else params,
            params_std={k: v for k, v in cal.std.items() if not k.startswith("nuisance")},
            n_params=cal.n_params - len(NUISANCE), heldout_after=E, cmp=cmp,
            details=details, state=cal)

    def _calibrate(self, names, classes=None, **kw):
        classes = classes if classes is not None else [EFFECTS[n] for n in names]
        b = self.budget
        kw = {"max_nfev": b.max_nfev, "jacobian_refresh": b.jacobian_refresh,
              "settled_sigma": b.settled_sigma, "probes_per_parameter": b.probes_per_parameter,
              "n_short": b.short_starts, "seed": b.random_state, **kw}
        # the probe cache only saves work, it changes no result: not part of the key
        return self.checkpoint.step(
            "calibrate", [self.model, self.train, list(classes), kw, self.rule],
            lambda: calibrate(self.model, self.meas, self.train, classes,
                              probe_cache=self._probe_costs, rule=self.rule, **kw))

    def _best(self, names, **kw):
        """Each discrete setting (a crack's station, a rub's disk) converged on the
        training speeds and chosen, as candidates are, on the held-out ones: the
        training cost barely tells stations apart."""
        fits = sorted((self._result(names, cal)
                       for cal in self._calibrate(names, each_discrete=True, **kw)),
                      key=lambda f: (f.heldout_after, f.state.cost))
        if len(fits) > 1:
            classes = [EFFECTS[n] for n in names]
            settings = [{c.name: discrete_settings(f.state, i, c)
                         for i, c in enumerate(classes) if c.discrete} for f in fits]
            fits[0].details.update(setting_rows(
                [(st, f, False) for st, f in zip(settings, fits, strict=True)],
                self.rule, self.budget))
            fits[0].settings_tried = {setting_key(st): f
                                      for st, f in zip(settings, fits, strict=True)}
            self.absorb(fits[0])
        return fits[0]

    def fit(self, names):
        return self._best(names, starts=[self.nuis_start], n_probe=self.budget.n_probe)

    def continue_fit(self, fit):
        # pairs start from the lead's first fit, whatever its continuation does; the
        # continuation keeps the fit's discrete settings and their evidence
        self._lead_x = fit.state.x
        fixed = [discrete_settings(fit.state, i, EFFECTS[n]) for i, n in enumerate(fit.effects)]
        more = self._result(fit.effects, self._calibrate(fit.effects, starts=[fit.state.x],
                                                         n_probe=0, fixed=fixed))
        more.details.update({k: fit.details[k] for k in SETTING_KEYS if k in fit.details})
        return more

    def _pair_kw(self, lead):
        # only the partner is probed; the lead keeps its discrete settings and starts
        # from its first fit. The partners' probes and the pairs' fits share these
        # keywords, so a pair reuses its partner's probe costs
        x0 = self._lead_x if self._lead_x is not None else lead.state.x
        b = self.budget
        return {"starts": [x0], "probe_from": len(x0), "n_probe": b.n_probe,
                "probes_per_parameter": b.pair_probes_per_parameter,
                "n_short": b.pair_short_starts,
                "fixed": [discrete_settings(lead.state, 0, EFFECTS[lead.effects[0]]), None]}

    def partners(self, lead, others, k, n_jobs=None):
        # an effect masked by a dominant one fits badly on its own: score each candidate
        # by probing it on top of the leading fit instead
        costs = run_parallel(n_jobs, [
            lambda p=p: self._calibrate((lead.effects[0], p), max_nfev=0,
                                        **self._pair_kw(lead)).cost for p in others],
            f"partners of {lead.effects[0]}")
        return [p for _, p in sorted(zip(costs, others, strict=True))[:k]]

    def fit_pair(self, lead, partner):
        return self._best((lead.effects[0], partner), **self._pair_kw(lead))

    def refit_members(self, pair):
        # a pair must not take the credit for one member's convergence: each member
        # runs alone from the pair's fit
        x = pair.state.x
        k = len(NUISANCE)
        blocks = effect_blocks(x, [EFFECTS[n] for n in pair.effects])
        out = []
        for member in (0, 1):
            name = pair.effects[member]
            start = np.concatenate([x[:k], blocks[member]])
            setting = discrete_settings(pair.state, member, EFFECTS[name])
            cal = self._calibrate((name,), starts=[start], n_probe=0, fixed=[setting])
            refit = self._result((name,), cal)
            # the member's setting came from the pair: its single's evidence holds only
            # where the single chose the same one
            first = next(iter(self._setting_fits.get((name,), {}).values()), None)
            if first is not None:
                single = first.details
                same = single["discrete_settings"][0]["setting"].get(name) == setting
                refit.details.update({"discrete_settings": single["discrete_settings"],
                                      "setting_decided": same and single["setting_decided"]})
            out.append(refit)
        return out

    def recheck_setting(self, fit):
        # each other setting's own search started from its probes and may have missed
        # the basin the chosen one found; started from the chosen fit it may reach it
        rows = fit.details.get("discrete_settings")
        if not rows:
            return None
        classes = [EFFECTS[n] for n in fit.effects]
        chosen = {c.name: discrete_settings(fit.state, i, c)
                  for i, c in enumerate(classes) if c.discrete}
        own = self._setting_fits.get(fit.effects, {})
        reps = {setting_key(chosen): (chosen, fit, False)}
        for row in rows:
            key = setting_key(row["setting"])
            if key in reps:
                continue
            fixed = [row["setting"].get(c.name) if c.discrete else None for c in classes]
            again = self._result(fit.effects, self._calibrate(
                fit.effects, starts=[fit.state.x], n_probe=0, fixed=fixed))
            first = own.get(key)
            better_first = first is not None and first.heldout_after <= again.heldout_after
            reps[key] = ((row["setting"], first, False) if better_first
                         else (row["setting"], again, True))
        # a model-error member (the linear-form test) is not refitted with the setting:
        # such a verdict keeps its setting and only learns how firmly it was chosen
        movable = not fit.details.get("model_error")
        best_key = min(reps, key=lambda k: reps[k][1].heldout_after) if movable else \
            setting_key(chosen)
        best = reps[best_key][1]
        others = sorted((v for k, v in reps.items() if k != best_key),
                        key=lambda v: v[1].heldout_after)
        entries = setting_rows([reps[best_key], *others], self.rule, self.budget)
        return entries, (None if best is fit else best)

    def linear_forms(self, fit):
        # the member's linear form starts from its fitted instance, the others keep
        # their fit and discrete settings: only the restriction is tested
        k = len(NUISANCE)
        classes = [EFFECTS[n] for n in fit.effects]
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
            cal = self._calibrate(fit.effects, swapped, starts=[start], n_probe=0, fixed=fixed)
            out.append(self._result(fit.effects[:i] + fit.effects[i + 1:], cal, swapped))
        return out
