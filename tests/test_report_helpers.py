"""The shared report helpers: quantities with units, bound flags, provenance, empty tables."""

import math
import os

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx._report import at_bound, page, provenance, quantity, table


def test_quantities_carry_units_and_few_digits():
    assert quantity(1648.2, "rpm") == "1648 rpm"
    assert quantity(3.8e-6, "m") == "3.8e-06 m"
    assert quantity(0.0345, "m") == "0.0345 m"
    assert quantity(999999999.9995, "N/m") == "1e+09 N/m"
    assert quantity(0.87, "-") == "0.870"
    assert quantity(None) == "-" and quantity(float("inf"), "m") == "inf"


@given(st.floats(-1e12, 1e12, allow_nan=False).filter(lambda v: v != 0))
def test_a_quantity_reads_back_to_its_value_within_its_digits(v):
    text = quantity(v, "m", digits=3)
    assert text.endswith(" m") and len(text) < 16
    back = float(text[:-2])
    assert math.isclose(back, v, rel_tol=6e-3, abs_tol=1e-300)


def test_values_on_their_search_bound_are_flagged():
    assert at_bound(999999999.9995, 1e6, 1e9, "log") == "upper"
    assert at_bound(1e6 * 1.0001, 1e6, 1e9, "log") == "lower"
    assert at_bound(3e7, 1e6, 1e9, "log") is None
    assert at_bound(0.0, 0.0, 0.6) == "lower" and at_bound(0.3, 0.0, 0.6) is None


def test_provenance_and_page():
    p = provenance("sknarx gap --measured m.csv --out o")
    assert {"sknarx_version", "commit", "date_utc", "python", "dependencies", "command"} <= set(p)
    assert p["dependencies"]["numpy"]
    text = page("Title", "<p>body</p>", p)
    assert "Regenerate with" in text and p["date_utc"] in text and "numpy" in text


def test_an_empty_table_says_why():
    assert "nothing significant" in table([], ["a"], empty="nothing significant")
    assert "<table>" in table([[1, "x"]], ["a", "b"])


def test_what_the_search_tested_reads_in_the_ranking_table_even_for_a_diverged_fit():
    from sknarx.gap.report import _discrete_text, _linear_form_text

    entry = {"discrete_settings": [
        {"setting": {"crack": {"station": "A-O1"}}, "heldout_gap_after": 120.25},
        {"setting": {"crack": {"station": "O2-B"}}, "heldout_gap_after": "inf"}],
        "linear_form_tests": [{"member": "anisotropy", "linear_form": "support-flexibility",
                               "heldout_gap_after": 310.0, "score": 316.0,
                               "outcome": "effect"}]}
    assert _discrete_text(entry) == "held-out excess by setting: crack A-O1 120.2; crack O2-B inf"
    assert "support-flexibility: an effect (the linear form leaves 310)" in _linear_form_text(entry)
    assert _discrete_text({}) == _linear_form_text({}) == ""


def test_a_verdict_naming_runout_says_a_bent_shaft_reads_the_same():
    """The headline of a verdict names what such data cannot tell each named effect
    from (its class's ``alike``): a runout, alone or in a pair, from a shaft bow; an
    effect with nothing alike adds nothing."""
    from sknarx.gap.report import alike_text
    from sknarx.rotor import EFFECTS

    alone = alike_text("runout")
    assert alone.startswith(" These data cannot tell the runout from a bent shaft")
    assert "a speed measured again after the sweep" in alone
    assert alike_text(["crack", "runout"]) == alone
    assert alike_text("crack") == "" and not EFFECTS["crack"].alike


def test_an_output_is_written_whole_or_not_at_all(tmp_path):
    """A run stopped mid-write leaves the previous file and no temporary beside it: every
    report, table and figure goes through io.write_atomic."""
    from sknarx.io import write_atomic, write_text_atomic

    path = write_text_atomic(tmp_path / "out" / "diagnosis.json", '{"verdict": "no-gap"}')

    def dies_halfway(tmp):
        with open(tmp, "w") as f:
            f.write('{"verd')
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_atomic(path, dies_halfway)
    assert path.read_text() == '{"verdict": "no-gap"}'
    assert [p.name for p in path.parent.iterdir()] == ["diagnosis.json"]
    # readable as a plain write would have left it (mkstemp's files are private)
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
