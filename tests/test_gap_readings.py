"""Alternative readings of the nominal rotor as a discrete setting (sknarx.gap.readings)."""

import numpy as np
import pytest

from sknarx.gap.readings import check_readings, reading_contenders
from sknarx.gap.report import candidate_label as _candidate_label
from sknarx.gap.report_text import reading_text as _reading_text


@pytest.mark.parametrize(
    "readings, match",
    [
        (["tilt_share_O"], "must map a label"),
        ({"": {"tilt_share_O": 1.0}}, "non-empty string"),
        ({"tilt": {}}, "at least one rotor parameter"),
        ({"tilt": {"tilt_shar_O": 1.0}}, r"unknown rotor parameter\(s\) \['tilt_shar_O'\]"),
        ({"tilt": {"tilt_share_O": "one"}}, r"sets \['tilt_share_O'\] to a non-number"),
        ({"tilt": {"tilt_share_O": True}}, "non-number"),
        # the rotor's own validation, before any fit
        ({"tilt": {"tilt_share_O": 2.0}}, r"Reading 'tilt' is not a rotor: .*between 0 and 1"),
        ({"soft": {"k1": -1.0}}, r"Reading 'soft' is not a rotor: .*positive"),
    ],
)
def test_a_malformed_reading_is_named_with_what_is_wrong(readings, match):
    with pytest.raises(ValueError, match=match):
        check_readings(readings)


def test_readings_are_plain_numbers_and_none_is_no_reading():
    assert check_readings(None) == {} and check_readings({}) == {}
    got = check_readings({"tilt": {"tilt_share_O": 1, "c_O1": np.float64(50.0)}})
    assert got == {"tilt": {"tilt_share_O": 1.0, "c_O1": 50.0}}
    assert all(type(v) is float for v in got["tilt"].values())


def test_the_contenders_are_the_best_distinct_singles():
    ranking = [{"effect": ["crack", "rub"]}, {"effect": "crack"}, {"effect": []},
               {"effect": "crack"}, {"effect": "looseness"}, {"effect": "rub"}]
    assert reading_contenders(ranking, 2) == ("crack", "looseness")
    assert reading_contenders(ranking, 5) == ("crack", "looseness", "rub")
    assert reading_contenders([], 2) == ()


def test_the_report_names_the_reading_a_fit_was_made_in():
    assert _candidate_label({"effect": "looseness"}) == "looseness"
    assert _candidate_label({"effect": []}) == "model error only"
    assert _candidate_label({"effect": "looseness", "rotor_reading": "tilt"}) == \
        "looseness (in reading 'tilt')"
    assert _candidate_label({"effect": [], "rotor_reading": "tilt"}) == \
        "rotor reading 'tilt' alone"
    doc = {"rotor_reading": {"label": "tilt", "changes": {"tilt_share_O": 1.0}},
           "rotor_readings": [{"label": "tilt", "heldout_gap_alone": 41.25}]}
    text = _reading_text(doc)
    assert "'tilt' (tilt_share_O = 1)" in text and "41.25" in text
    assert "own nominal update" not in text
    doc["rotor_readings"][0]["nominal_update"] = {"updates": ["k2: -25.0 % +- 10.2 %"]}
    assert "the reading's own nominal update: k2: -25.0 % +- 10.2 %." in _reading_text(doc)
    assert _reading_text({}) == ""


@pytest.mark.slow
def test_a_reading_that_changes_nothing_fits_what_the_rotor_as_given_fits(tmp_path):
    """The readings are compared on the rotor as given's features and tolerance: a
    reading equal to that rotor repeats its update, its nuisance-only model and its
    contenders' fits exactly, and decides as it does."""
    from sknarx.gap import diagnose
    from sknarx.testing import make_trial

    speeds = tuple(np.linspace(81.7, 276.5, 6).round(4))
    measured, _ = make_trial("runout", 7, speeds=speeds, n_samples=1000)
    d = diagnose(measured, candidates=("runout",),
                 readings={"as given": {"tilt_share_O": 0.0}})
    entry = d["rotor_readings"][0]
    assert entry["contenders"] == ["runout"] and entry["label"] == "as given"
    assert entry["nominal_update"]["chi2"] == d["nominal_update"]["chi2"]
    assert entry["heldout_gap_alone"] == pytest.approx(d["gap_before"]["heldout_excess"])
    mine = [r for r in d["ranking"] if r.get("rotor_reading") == "as given"]
    given = [r for r in d["ranking"] if "rotor_reading" not in r]
    assert [r["effect"] for r in mine] == ["runout", []] and len(given) == 1
    assert mine[1]["shrink"] == pytest.approx(0.0, abs=1e-12)
    assert mine[0]["heldout_gap_after"] == pytest.approx(given[0]["heldout_gap_after"])
    assert d["verdict"] == "runout"
    # the report's ranking names the reading each fit was made in
    from sknarx.gap.report import write_gap_outputs

    doc = write_gap_outputs(d, tmp_path, "sknarx gap ...")
    html = (tmp_path / "report.html").read_text()
    assert "runout (in reading &#x27;as given&#x27;)" in html
    assert "rotor reading &#x27;as given&#x27; alone" in html
    assert doc["rotor_readings"][0]["label"] == "as given"
