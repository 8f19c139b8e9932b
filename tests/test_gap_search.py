"""The search over candidates, effect or model error, and the discrete settings."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx.gap import Candidate, SearchBudget, VerdictRule, diagnose
from sknarx.gap.document import verdict_entries
from sknarx.gap.report_text import linear_form_text, verdict_text
from sknarx.gap.search import FrontEnd, rank, recheck_setting, search

SPEEDS = tuple(np.linspace(81.7, 276.5, 6).round(4))


def _given_fit(names, E, n_params, model_error=None):
    """A candidate with a held-out table of 100 features sharing ``E`` equally."""
    cmp = pd.DataFrame({"speed": np.repeat(np.arange(10.0), 10), "window": "steady",
                        "channel": "xA", "feature": np.tile([f"f{i}" for i in range(10)], 10),
                        "excess": E / 100.0, "gap": 1e-6})
    return Candidate(effects=tuple(names), params=[{}] * len(names) if len(names) != 1
                     else {}, params_std={}, n_params=n_params, heldout_after=E, cmp=cmp,
                     details={"model_error": model_error} if model_error else {})


class _GivenFits(FrontEnd):
    """A front end whose fits are given, so the search's rules can be read alone."""

    def __init__(self, fits, forms):
        self.fits, self.forms, self.asked = fits, forms, []

    def fit(self, names):
        return self.fits[names]

    def fit_pair(self, lead, partner):
        return self.fits[(lead.effects[0], partner)]

    def linear_forms(self, fit):
        self.asked.append(fit.effects)
        return self.forms.get(fit.effects, [])


def _search_given(fits, forms, e0=20.0, budget=None, **rule):
    rule = VerdictRule(**rule)
    budget = budget or SearchBudget(n_bootstrap=20)
    front = _GivenFits(fits, forms)
    E0 = 100 * e0
    cmp0 = _given_fit((), E0, 0).cmp
    ranked = search(front, [n[0] for n in fits if len(n) == 1], E0, cmp0, 100, rule, budget)
    verdict = rule.decide(e0, ranked, None, 100)
    doc = verdict_entries(verdict, ranked, cmp0, [], rule, budget, 100)
    return front, ranked, doc


def test_a_partner_that_only_changes_the_linear_rotor_is_model_error_not_an_effect():
    # a rub came out as rub + anisotropy, the anisotropy's two pedestal stiffnesses
    # within 4-30 % of each other: a soft support, which is model error
    support = {"support-flexibility": {"k": 1.07e7, "mass": 31.8, "damping": 6046.0}}
    fits = {("rub",): _given_fit(["rub"], 400.0, 5),
            ("anisotropy",): _given_fit(["anisotropy"], 1500.0, 4),
            ("rub", "anisotropy"): _given_fit(["rub", "anisotropy"], 100.0, 9)}
    # the isotropic form does as well (one parameter fewer buys two of excess)
    forms = {("rub", "anisotropy"): [_given_fit(["rub"], 101.5, 8, support)]}
    front, ranked, doc = _search_given(fits, forms)
    assert ("rub", "anisotropy") in front.asked
    assert doc["verdict"] == "rub" and doc["model_error"] == support
    assert [c.heldout_after for c in ranked if c.effects == ("rub",)] == [101.5]
    assert not any(c.effects == ("rub", "anisotropy") for c in ranked)
    # an anisotropic support does what the isotropic one cannot: the pair stands
    forms = {("rub", "anisotropy"): [_given_fit(["rub"], 160.0, 8, support)]}
    _, ranked, doc = _search_given(fits, forms)
    assert doc["verdict"] == ["rub", "anisotropy"] and "model_error" not in doc


def test_pairs_are_searched_below_the_trigger_that_names_them_and_said_so():
    """A weak second effect beside a dominant one (a mild anisotropy under a runout
    leaving 0.3 per feature): pairs are searched from the budget's ``pair_search_from``
    (0.1) and ranked, but named only where the single leaves more than the rule's
    ``pair_trigger`` (0.5); the verdict names the single and says which pair it did not
    name and why."""
    fits = {("runout",): _given_fit(["runout"], 30.0, 12),
            ("anisotropy",): _given_fit(["anisotropy"], 1500.0, 4),
            ("runout", "anisotropy"): _given_fit(["runout", "anisotropy"], 9.0, 16)}
    _, ranked, doc = _search_given(fits, {})
    assert ranked[0].effects == ("runout", "anisotropy")
    assert doc["verdict"] == "runout"
    under = doc["pair_under_trigger"]
    assert under["effect"] == ["runout", "anisotropy"] and under["single"] == "runout"
    assert under["single_leaves_per_feature"] == pytest.approx(0.3)
    assert under["removes_of_single"] == pytest.approx(0.7)
    assert under["pair_trigger"] == 0.5
    doc.update(gap_before={"per_feature": 20.0}, settings={"rule": VerdictRule().to_dict()},
               ranking=[c.to_entry() for c in ranked])
    assert ("The pair runout + anisotropy removes 99.6 % of the held-out gap but is not "
            "named: the best single leaves 0.3 held-out excess per feature, not more than "
            "the 0.5 above which a pair may be named.") in verdict_text(doc)
    # searched only from the trigger: no pair, nothing to say
    _, ranked, doc = _search_given(fits, {}, budget=SearchBudget(pair_search_from=0.5))
    assert all(len(c.effects) == 1 for c in ranked)
    assert doc["verdict"] == "runout" and "pair_under_trigger" not in doc
    # a lead leaving less than the search's start gets no partner
    fits[("runout",)] = _given_fit(["runout"], 8.0, 12)
    _, ranked, _ = _search_given(fits, {})
    assert all(len(c.effects) == 1 for c in ranked)
    # above the trigger the pair is named, and nothing is set aside
    fits[("runout",)] = _given_fit(["runout"], 80.0, 12)
    _, _, doc = _search_given(fits, {})
    assert doc["verdict"] == ["runout", "anisotropy"] and "pair_under_trigger" not in doc


def test_an_effect_left_with_model_error_alone_is_a_no_gap_verdict_with_it_stated():
    support = {"support-flexibility": {"k": 3e7, "mass": 12.0, "damping": 900.0}}
    # 0.08 per feature: under the pair search's start (0.1), so no pairs
    fits = {("anisotropy",): _given_fit(["anisotropy"], 8.0, 4),
            ("crack",): _given_fit(["crack"], 1200.0, 3)}
    forms = {("anisotropy",): [_given_fit([], 8.5, 3, support)]}
    _, ranked, doc = _search_given(fits, forms)
    assert doc["verdict"] == "no-gap" and doc["model_error"] == support
    assert doc["shrink"] == 0.0 and ranked[0].effects == ()
    # where the isotropic support leaves more, the anisotropy is the effect
    forms = {("anisotropy",): [_given_fit([], 90.0, 3, support)]}
    _, _, doc = _search_given(fits, forms)
    assert doc["verdict"] == "anisotropy"


def test_the_best_single_and_the_best_pair_are_both_tested_whatever_the_rule():
    """The effect-or-model-error test does not depend on which of the two contenders
    the rule prefers; each entry says what the test found."""
    support = {"support-flexibility": {"k": 2e7, "mass": 15.0, "damping": 800.0}}
    fits = {("anisotropy",): _given_fit(["anisotropy"], 150.0, 4),  # 1.5 per feature
            ("crack",): _given_fit(["crack"], 1200.0, 3),
            ("anisotropy", "crack"): _given_fit(["anisotropy", "crack"], 60.0, 7)}
    # the lone anisotropy is only a soft support; in the pair it is more than that
    forms = {("anisotropy",): [_given_fit([], 151.0, 3, support)],
             ("anisotropy", "crack"): [_given_fit(["crack"], 300.0, 6, support)]}
    front, ranked, doc = _search_given(fits, forms)
    assert set(front.asked) == {("anisotropy",), ("anisotropy", "crack")}
    assert doc["verdict"] == ["anisotropy", "crack"]
    pair = next(c for c in ranked if c.effects == ("anisotropy", "crack"))
    assert pair.details["linear_form_tests"][0]["outcome"] == "effect"
    assert linear_form_text(pair.to_entry(), 0.3).endswith(
        "it removes 80 % of what the form leaves: an effect")
    alone = next(c for c in ranked if c.effects == ())
    assert alone.details["replaces"]["effect"] == ["anisotropy"]
    assert not any(c.effects == ("anisotropy",) for c in ranked)
    assert "replaces anisotropy" in linear_form_text(alone.to_entry(), 0.3)
    # a rule that keeps the single: the single is the support, tested already -- no-gap
    # with the model error
    v = VerdictRule(min_gain=0.9).decide(20.0, ranked, None, 100)
    assert v.outcome == "no-gap" and v.named is alone


def test_a_contender_left_out_by_its_linear_form_makes_the_next_one_tested():
    """A pair whose member beat its form by too little (less than ``min_gain`` of what
    the form leaves) is out of the verdict; the pair the verdict would then name must
    face the same test, not be named untested."""
    support = {"support-flexibility": {"k": 2e7, "mass": 15.0, "damping": 800.0}}
    fits = {("rub",): _given_fit(["rub"], 400.0, 5),
            ("anisotropy",): _given_fit(["anisotropy"], 1500.0, 4),
            ("clearance",): _given_fit(["clearance"], 1800.0, 2),
            ("rub", "anisotropy"): _given_fit(["rub", "anisotropy"], 100.0, 9),
            ("rub", "clearance"): _given_fit(["rub", "clearance"], 150.0, 7)}
    # the anisotropy beats its form (score 126 against 118) but removes 9 % of what it
    # leaves; the clearance in the next pair is no more than a linear change either
    forms = {("rub", "anisotropy"): [_given_fit(["rub"], 110.0, 8, support)],
             ("rub", "clearance"): [_given_fit(["rub"], 151.0, 6, support)]}
    front, ranked, doc = _search_given(fits, forms)
    assert ("rub", "clearance") in front.asked
    assert doc["verdict"] == "rub" and doc["model_error"] == support
    assert not any(c.effects == ("rub", "clearance") for c in ranked)
    # a rule asking nothing beyond the form names the pair and tests no further
    front, _, doc = _search_given(fits, forms, min_gain=0.0)
    assert ("rub", "clearance") not in front.asked
    assert doc["verdict"] == ["rub", "anisotropy"]


@pytest.mark.slow
def test_a_soft_isotropic_support_is_model_error_not_an_anisotropy():
    """End to end on the sweep front end: housings on a soft pedestal, the same in x and
    y, fit as an anisotropy with nearly equal stiffnesses; the isotropic form does as
    well, so the verdict is no-gap with the support stated as model error."""
    from sknarx.rotor import MeasurementNoise, RotorBearingSimulator, SupportFlexibility

    support = SupportFlexibility(k=4e6, mass=30.0, damping=1000.0)
    sim = RotorBearingSimulator(effects=[support, MeasurementNoise(snr_db=35.0)], seed=3)
    measured = sim.sweep(list(SPEEDS), fs=1000.0, n_samples=1000, settle=0.0,
                         progress=False)[["speed", "t", "xO1", "yO1", "xA", "yA"]]
    fast = SearchBudget(n_probe=8, max_nfev=8)
    d = diagnose(measured, candidates=("anisotropy",), budget=fast, update=False)
    assert d["gap_before"]["per_feature"] > 10 * d["gap_before"]["floor"]["floor_per_feature"]
    assert d["verdict"] == "no-gap" and d["ranking"][0]["effect"] == []
    fitted = d["model_error"]["support-flexibility"]
    assert fitted == d["ranking"][0]["model_error"]["support-flexibility"]
    assert 0.5 < fitted["k"] / support.k < 2.0


def test_support_flexibility_is_the_anisotropy_with_equal_stiffnesses():
    from sknarx.rotor import RotorBearingSimulator, SupportAnisotropy, SupportFlexibility

    aniso = SupportAnisotropy(kx=8e6, ky=8e6, mass=20.0, damping=500.0, probes="frame")
    form = aniso.linear_form_of()
    assert isinstance(form, SupportFlexibility)
    assert SupportAnisotropy.linear_form is SupportFlexibility
    assert (form.k, form.mass, form.damping, form.probes) == (8e6, 20.0, 500.0, "frame")
    a = RotorBearingSimulator(effects=[aniso]).simulate_columns(150.0, n_samples=200, settle=0.1)
    b = RotorBearingSimulator(effects=[form]).simulate_columns(150.0, n_samples=200, settle=0.1)
    for col in ("xA", "yA", "xO1", "yB"):
        np.testing.assert_array_equal(a[col], b[col])
    with pytest.raises(ValueError, match="probes"):
        SupportFlexibility(probes="shaft")


# ------------------------------------------------- how firmly a discrete setting is chosen
_speeds_excess = st.lists(st.tuples(st.floats(0, 50), st.floats(0, 50)), min_size=1,
                          max_size=12)


@given(_speeds_excess, st.integers(0, 2**16))
def test_setting_support_is_antisymmetric_and_a_share(pairs, seed):
    """The share of resamples preferring one table over another and the share preferring
    the other add to one (the tables are paired speed by speed, ties split)."""
    from sknarx.gap.evidence import setting_support

    speeds = np.arange(len(pairs), dtype=float)
    a = pd.DataFrame({"speed": speeds, "excess": [p[0] for p in pairs]})
    b = pd.DataFrame({"speed": speeds, "excess": [p[1] for p in pairs]})
    ab, ba = setting_support(a, b, 64, seed), setting_support(b, a, 64, seed)
    assert 0.0 <= ab <= 1.0
    assert ab + ba == pytest.approx(1.0)
    # a setting that leaves more at every speed is never preferred; a diverged one always
    worse = b.assign(excess=np.maximum(a.excess, b.excess) + 1.0)
    assert setting_support(a, worse, 64, seed) == 1.0
    assert setting_support(a, None, 64, seed) == 1.0


def test_a_setting_is_decided_only_against_every_other():
    """Decided where the held-out speeds prefer the chosen setting over every other in
    the rule's ``setting_support`` (1 - false_alarm) of bootstrap resamples."""
    from types import SimpleNamespace

    from sknarx.gap.sweep_front import setting_rows

    cmp = pd.DataFrame({"speed": [1.0, 2.0, 3.0], "excess": [1.0, 1.0, 1.0]})
    chosen = SimpleNamespace(heldout_after=3.0, cmp=cmp, state=SimpleNamespace(cost=1.0))
    clearly = SimpleNamespace(heldout_after=30.0, cmp=cmp.assign(excess=10.0),
                              state=SimpleNamespace(cost=2.0))
    close = SimpleNamespace(heldout_after=3.1, cmp=cmp.assign(excess=[1.1, 0.9, 1.1]),
                            state=SimpleNamespace(cost=2.0))
    budget = SearchBudget(n_bootstrap=200)
    rows = [({"crack": {"station": s}}, f, False) for s, f in
            (("A-O1", chosen), ("joint", clearly), ("O2-B", close))]
    assert setting_rows(rows, VerdictRule(), budget)["setting_decided"] is False
    assert setting_rows(rows[:2], VerdictRule(), budget)["setting_decided"] is True
    assert setting_rows(rows[:1], VerdictRule(), budget)["setting_decided"] is False


def _stub_front_end(monkeypatch, setting):
    """The time-series front end with its fits stubbed out: only what it carries from
    one fit to the next is exercised."""
    from types import SimpleNamespace

    from sknarx.gap import sweep_front

    monkeypatch.setattr(sweep_front, "discrete_settings", lambda state, i, cls: setting)
    monkeypatch.setattr(sweep_front, "effect_blocks", lambda x, classes: [x[:1], x[1:]])
    fe = object.__new__(sweep_front.SweepFrontEnd)
    fe._lead_x, fe._setting_fits = None, {}
    fe.rule, fe.budget = VerdictRule(), SearchBudget()
    fe._calibrate = lambda names, **kw: None
    fe._result = lambda names, cal: Candidate(names, {}, {}, 5, 1.0, None, {}, None)

    def fit(names, details):
        return Candidate(names, {}, {}, 5, 2.0, None, details,
                         SimpleNamespace(x=np.zeros(len(sweep_front.NUISANCE) + 2)))
    return fe, fit


def test_a_continued_or_refitted_candidate_keeps_its_setting_evidence(monkeypatch):
    """The lead's continuation and a pair member's refit replace the first fit in the
    ranking: the evidence on its discrete setting (how firmly the held-out speeds chose
    the rub's disk) must survive, and a member whose pair moved it elsewhere is not
    decided."""
    rows = [{"setting": {"rub": {"at": "O1"}}, "heldout_gap_after": 69.0},
            {"setting": {"rub": {"at": "O2"}}, "heldout_gap_after": 80.0,
             "chosen_preferred_share": 0.9}]
    fe, fit = _stub_front_end(monkeypatch, {"at": "O1"})
    lead = fit(("rub",), {"discrete_settings": rows, "setting_decided": False})
    more = fe.continue_fit(lead)
    assert more.details["discrete_settings"] is rows
    assert more.details["setting_decided"] is False

    single = {"discrete_settings": rows, "setting_decided": True}
    fe._setting_fits[("rub",)] = {"O1": fit(("rub",), single)}
    pair = fit(("rub", "runout"), {})
    member = fe.refit_members(pair)[0]
    assert member.details["setting_decided"] is True
    fe, fit = _stub_front_end(monkeypatch, {"at": "O2"})  # the pair put the rub at O2
    fe._setting_fits[("rub",)] = {"O1": fit(("rub",), single)}
    member = fe.refit_members(fit(("rub", "runout"), {}))[0]
    assert member.details["setting_decided"] is False


def test_the_verdicts_other_settings_are_refitted_from_its_own_fit(monkeypatch):
    """A setting whose own search missed the basin the chosen one found is no evidence
    against it: refitted from the verdict's fit it reaches nearly the same held-out
    excess, and the setting is then not decided."""
    fe, fit = _stub_front_end(monkeypatch, {"at": "O1"})
    cmp = pd.DataFrame({"speed": [1.0, 2.0, 3.0], "excess": [1.0, 1.0, 1.0]})
    rows = [{"setting": {"rub": {"at": "O1"}}, "heldout_gap_after": 3.0,
             "training_cost": 10.0},
            {"setting": {"rub": {"at": "O2"}}, "heldout_gap_after": 50.0,
             "training_cost": 40.0, "chosen_preferred_share": 1.0}]
    verdict = fit(("rub",), {"discrete_settings": rows, "setting_decided": True})
    verdict.cmp, verdict.heldout_after = cmp, 3.0
    verdict.state.cost = 10.0
    seen = []

    def calibrate(names, **kw):
        seen.append(kw)
        return None
    fe._calibrate = calibrate
    fe._result = lambda names, cal: Candidate(
        names, {}, {}, 5, 3.1, cmp.assign(excess=[1.0, 1.1, 1.0]), {},
        type("State", (), {"cost": 10.5})())
    entries, better = fe.recheck_setting(verdict)
    # one refit: the other disk, held, started from the verdict's parameters
    assert len(seen) == 1 and seen[0]["fixed"] == [{"at": "O2"}]
    assert seen[0]["starts"][0] is verdict.state.x and seen[0]["n_probe"] == 0
    assert better is None  # the verdict's disk still fits best
    other = entries["discrete_settings"][1]
    assert other["from_chosen_fit"] and other["heldout_gap_after"] == 3.1
    assert other["chosen_preferred_share"] < VerdictRule().setting_support
    assert entries["setting_decided"] is False

    # refitted from the verdict's fit, the other end does better: it replaces the fit
    fe._result = lambda names, cal: Candidate(
        names, {"at": "B"}, {}, 5, 1.0, cmp.assign(excess=[0.2, 0.4, 0.4]), {},
        type("State", (), {"cost": 8.0})())
    entries, better = fe.recheck_setting(verdict)
    assert better is not None and better.heldout_after == 1.0
    rows = entries["discrete_settings"]
    assert rows[0]["from_chosen_fit"] and rows[0]["heldout_gap_after"] == 1.0
    assert rows[1]["setting"] == {"rub": {"at": "O1"}}
    assert rows[1]["chosen_preferred_share"] == 1.0 and entries["setting_decided"]


def test_a_better_setting_found_by_the_recheck_is_decided_again():
    """The core side of the recheck: the better fit replaces the verdict's in the
    ranking and the verdict is decided from the new ranking."""
    cmp0 = pd.DataFrame({"speed": [1.0, 2.0], "window": "steady", "channel": "xO1",
                         "feature": "1x", "excess": [50.0, 50.0], "z2": 52.0, "gap": 1e-6})
    first = Candidate(("misalignment",), {"at": "A"}, {}, 5, 40.0,
                      cmp0.assign(excess=[20.0, 20.0]),
                      {"discrete_settings": [{"setting": {}}]})
    other = Candidate(("crack",), {"station": "A-O1"}, {}, 3, 60.0,
                      cmp0.assign(excess=[30.0, 30.0]), {})
    better = Candidate(("misalignment",), {"at": "B"}, {}, 5, 10.0,
                       cmp0.assign(excess=[5.0, 5.0]), {})

    class Front(FrontEnd):
        def recheck_setting(self, fit):
            return {"discrete_settings": [], "setting_decided": True}, better

    ranked = rank([first, other], 100.0, cmp0)
    rule = VerdictRule(min_log_shrink=0.0)
    verdict = rule.decide(50.0, ranked, None, 2)
    assert verdict.named is first
    verdict, ranked = recheck_setting(Front(), verdict, ranked, 100.0, cmp0, rule, 2, None)
    assert verdict.named is better and better.params == {"at": "B"}
    assert better.details["setting_decided"] is True
    assert [c.params for c in ranked] == [{"at": "B"}, {"station": "A-O1"}]
