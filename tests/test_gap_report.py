"""Every branch of the gap report's generated sentences, from the values that decided it.

Each sentence reads a ``diagnosis.json`` document; these documents are built by hand
with exactly the keys a diagnosis writes, so that each branch is reached and its words
are checked against the numbers beside them.
"""

import pytest

from sknarx.cli import _verdict_line
from sknarx.gap import Shortfall, VerdictRule
from sknarx.gap.report_text import (
    _pct,
    alike_text,
    discrete_text,
    label,
    linear_form_text,
    passes_text,
    reading_text,
    setting_text,
    shortfall_sentences,
    verdict_text,
)
from sknarx.rotor import EFFECTS

RULE = VerdictRule().to_dict()


def doc(verdict, e0=4.0, floor=0.2, **more):
    """A document as a time-series diagnosis writes it, with ``more`` on top."""
    out = {"verdict": verdict, "shrink": 0.0, "ranking": [],
           "gap_before": {"per_feature": e0, "floor": {
               "floor_per_feature": floor, "noise_per_feature": 0.1, "false_alarm": 0.01}},
           "settings": {"rule": RULE}, "nominal_update": None}
    out.update(more)
    return out


def test_a_share_is_never_rounded_to_a_whole_it_is_short_of():
    assert _pct(0.6) == "60 %" and _pct(1.0) == "100 %"
    assert _pct(0.996) == "99.6 %" and _pct(0.99999) == ">99.9 %"
    assert _pct(0.9999999988) == ">99.9 %"  # never "100 %" for a share short of one


def test_a_named_effect_states_its_share_and_the_gap_against_its_floor():
    d = doc("crack", shrink=0.83, shrink_above_noise=0.85, shrink_band=[0.7, 0.9],
            ranking=[{"effect": "crack", "log_shrink": 0.6}])
    text = verdict_text(d)
    assert text.startswith("crack removes 83 % of the held-out gap (bootstrap 5-95 %: 70 % "
                           "to 90 %), 85 % of what lies above the noise;")
    assert "the held-out gap was 4 per feature, above the 0.2 that the sweep's own noise " \
           "leaves at the 99 % level (its no-gap floor)." in text
    assert "although the gap is within the floor" not in text
    # the share above the noise is said only where it differs from the plain share
    assert "above the noise" not in verdict_text({**d, "shrink_above_noise": 0.832})


def test_an_effect_named_within_the_floor_says_why_with_the_rule_s_numbers():
    d = doc("runout", e0=0.15, floor=0.2, shrink=0.7, shrink_above_noise=0.9,
            ranking=[{"effect": "runout", "log_shrink": 0.45}])
    text = verdict_text(d)
    assert "within the 0.2 that the sweep's own noise leaves" in text
    assert ("It is named although the gap is within the floor because it passes the "
            "rule's tests of what is left: it removes 90 % of the gap above the noise (the "
            "rule asks 60 %) and 45 % of its logarithm (the rule asks 30 %).") in text


def test_no_gap_says_the_gap_is_within_the_floor_and_what_the_update_moved():
    d = doc("no-gap", e0=0.1)
    assert verdict_text(d) == (
        "No gap: the held-out gap was 0.1 per feature, within the 0.2 that the sweep's own "
        "noise leaves at the 99 % level (its no-gap floor), and no candidate passes the "
        "rule's tests of what is left.")
    d["nominal_update"] = {"updates": ["k1: -12 %", "c_a: +30 %"]}
    assert "; 2 nominal parameter(s) updated (model error, listed below)." in verdict_text(d)


def test_no_gap_by_model_error_names_the_linear_change():
    error = {"support-flexibility": {"k": 1e7, "mass": 20.0, "damping": 500.0}}
    text = verdict_text(doc("no-gap", model_error=error))
    assert text.startswith("No effect: the held-out gap was 4 per feature")
    assert "a change of the linear rotor explains it (support-flexibility: k 1e+07 N/m" in text
    assert "model error, however much of the gap it removes" in text
    reading = {"label": "tilt", "changes": {"tilt_share_O": 1.0}}
    assert "the rotor's reading 'tilt' explains it" in verdict_text(
        doc("no-gap", rotor_reading=reading))


def test_unexplained_names_the_closest_candidate_and_every_test_it_failed():
    rule = VerdictRule()
    shortfalls = [Shortfall("shrink", 0.45, rule.min_shrink).to_dict(),
                  Shortfall("breadth", 0.1, rule.min_log_shrink).to_dict()]
    d = doc("unexplained", shrink=0.5, closest={"effect": ["rub", "crack"],
                                                 "shortfalls": shortfalls})
    text = verdict_text(d)
    assert text.startswith("Unexplained: the held-out gap was 4 per feature, above the 0.2")
    assert "(the best removes 50 % of it)" in text
    assert text.endswith(
        "The closest candidate, rub + crack, removes 45 % of the held-out gap above the "
        "noise; the rule asks at least 60 %, and removes 10 % of the gap's logarithm (how "
        "broadly it fits); the rule asks at least 30 %.")
    # the same through the command line's verdict line
    assert _verdict_line(d) == "verdict: unexplained\n" + text
    assert "closest" not in verdict_text(doc("unexplained"))


@pytest.mark.parametrize("key, test, value, words", [
    ("rival_pair", "rival", 0.82, "each member alone removes at least 82 % of the gap above "
                                  "the noise, as a named effect must (60 %)"),
    ("pair_under_trigger", "pair-trigger", 0.31, "the best single leaves 0.31 held-out "
                                                 "excess per feature, not more than the 0.5"),
])
def test_a_pair_set_aside_is_said_with_the_test_that_set_it_aside(key, test, value, words):
    required = RULE["min_shrink"] if test == "rival" else RULE["pair_trigger"]
    note = {"effect": ["rub", "crack"], "shrink": 0.9,
            "shortfall": Shortfall(test, value, required).to_dict()}
    text = verdict_text(doc("rub", shrink=0.8, **{key: note}))
    assert "The pair rub + crack removes 90 % of the held-out gap but is not named: " \
           f"{words}" in text


def test_passes_that_differ_replace_the_verdict_text_and_those_that_agree_are_added():
    passes = {"changed": True, "band_rtol": 0.01, "z2_ratio": 40.0, "statistic": 25.0,
              "floor_sigmas": 2.326, "largest": [{"feature": "1x", "channel": "xO1",
                                                  "speed": 100.0}],
              "one_pass": {"verdict": "runout"}}
    text = verdict_text(doc("unexplained", passes=passes))
    assert text.startswith("The two passes of the sweep differ (beyond a dead band of 1 % of "
                           "each vector's size")
    assert "most at 1x on xO1 at 100 rad/s" in text and text.endswith(
        "The first pass alone: runout.")
    agree = {**passes, "changed": False, "statistic": 0.5}
    assert passes_text(doc("crack", passes=agree)).startswith(
        " The two passes of the sweep agree")
    assert passes_text(doc("crack")) == ""


def test_an_undecided_setting_is_said_at_the_rule_s_level():
    assert setting_text(doc("crack", setting_decided=True)) == ""
    assert "fewer than 99 % of bootstrap resamples" in setting_text(
        doc("crack", setting_decided=False))


def test_what_cannot_be_told_apart_and_the_reading_of_a_verdict():
    alone = alike_text("runout")
    assert alone.startswith(" These data cannot tell the runout from a bent shaft")
    assert alike_text(["crack", "runout"]) == alone
    assert alike_text("crack") == "" and not EFFECTS["crack"].alike
    d = {"rotor_reading": {"label": "tilt", "changes": {"tilt_share_O": 1.0}},
         "rotor_readings": [{"label": "tilt", "heldout_gap_alone": 41.25,
                             "nominal_update": {"updates": ["k2: -25.0 %"]}}]}
    text = reading_text(d)
    assert "'tilt' (tilt_share_O = 1)" in text and "41.25" in text
    assert text.endswith("the reading's own nominal update: k2: -25.0 %.")
    assert reading_text({}) == ""


def test_the_ranking_s_evidence_reads_even_for_a_diverged_fit():
    entry = {"heldout_gap_after": 100.0, "discrete_settings": [
        {"setting": {"crack": {"station": "A-O1"}}, "heldout_gap_after": 120.25},
        {"setting": {"crack": {"station": "O2-B"}}, "heldout_gap_after": "inf",
         "chosen_preferred_share": 1.0}], "setting_decided": True,
        "linear_form_tests": [{"member": "anisotropy", "linear_form": "support-flexibility",
                               "heldout_gap_after": 310.0}]}
    assert discrete_text(entry) == ("held-out excess by setting: crack A-O1 120.2; crack "
                                    "O2-B inf (the first preferred in 100 % of resamples); "
                                    "setting decided")
    assert linear_form_text(entry, 0.3) == (
        "anisotropy tested against its linear form support-flexibility (which leaves 310); "
        "it removes 68 % of what the form leaves: an effect")
    assert "model error, left out of the verdict (the rule asks 80 %)" in linear_form_text(
        entry, 0.8)
    diverged = {**entry, "heldout_gap_after": "inf"}
    assert linear_form_text(diverged, 0.3).endswith("(which leaves 310)")
    assert discrete_text({}) == linear_form_text({}, 0.3) == ""


def test_labels_and_shortfall_sentences():
    assert label("crack") == "crack" and label(["rub", "crack"]) == "rub + crack"
    assert label([]) == "model error only"
    s = Shortfall("linear-form", 0.1, 0.3)
    assert shortfall_sentences("x", [s]) == (
        "x removes 10 % of what its linear form (a change of the linear rotor, model "
        "error) leaves; the rule asks at least 30 %.")
    assert s.parameter == "min_gain" and shortfall_sentences("x", []) == ""
