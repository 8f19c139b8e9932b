"""Every branch of the paper report's generated sentences follows from its numbers."""

import numpy as np
import pandas as pd
import pytest

from sknarx._report import percentage
from sknarx.reproduce.text import (
    Z95,
    acceptance_text,
    aerr_text,
    change_text,
    coefficient_text,
    harmonics_text,
    targets_text,
)


def _summary(rel_errors):
    return pd.DataFrame({"term": [f"y(t-{i + 1})" for i in range(len(rel_errors))],
                         "speed": np.linspace(50, 300, len(rel_errors)),
                         "coef": 2.0, "std_err": 2.0 * np.asarray(rel_errors)})


def test_coefficients_are_called_determined_only_when_every_interval_excludes_zero():
    text = coefficient_text(_summary([0.01, 0.2, 0.4]), "m")
    assert "Every coefficient" in text and "40 %" in text and "determine them" in text
    # the case: a 257 % relative error is not "well determined"
    text = coefficient_text(_summary([0.01, 2.57, 0.6]), "m")
    assert "2 of the 3 coefficients" in text and "257 %" in text
    assert "includes zero" in text and "determine" in text and "Every" not in text
    assert f"{100 / Z95:.2g} %" in text
    assert "No standard error" in coefficient_text(
        _summary([0.1]).assign(std_err=np.nan), "m")


def test_the_boundary_of_determined_is_the_95_percent_interval():
    at = 1.0 / Z95
    assert "Every coefficient" in coefficient_text(_summary([at * 0.999]), "m")
    assert "1 of the 1" in coefficient_text(_summary([at * 1.001]), "m")


def _pooled(passed):
    return pd.DataFrame({"test": ["phi_ee", "phi_ue", "phi_e_eu", "phi_u2_e", "phi_u2_e2"],
                         "passed": passed})


@pytest.mark.parametrize("checks, tests, words, absent", [
    ([True, True], [True] * 5, ["All 2 acceptance points pass", "pass all 5"], ["fails"]),
    ([True, True], [False] * 5, ["All 2 acceptance points pass", "fails 5 of 5",
                                 "accurate enough for the paper's targets"], ["short of"]),
    ([True, False], [True, False, True, True, True],
     ["1 of the 2 acceptance points fail", "fails 1 of 5 (phi_ue)", "short of the paper's"],
     ["accurate enough"]),
    ([False, False], [True] * 5, ["2 of the 2 acceptance points fail", "pass all 5"], []),
])
def test_the_summary_says_how_the_acceptance_table_and_the_validity_tests_fit(
        checks, tests, words, absent):
    text = acceptance_text(checks, _pooled(tests), "m")
    for w in words:
        assert w in text, (w, text)
    for w in absent:
        assert w not in text, (w, text)


def test_the_targets_sentence_follows_the_limits():
    limits = {"nrmse": 0.05, "amp1x_rel_error": 0.02}
    good = pd.DataFrame({"nrmse": [0.01, 0.049], "amp1x_rel_error": [0.001, 0.019]})
    assert targets_text(good, limits).startswith("meets")
    for col, bad in (("nrmse", 0.051), ("amp1x_rel_error", 0.021)):
        text = targets_text(good.assign(**{col: [0.01, bad]}), limits)
        assert text.startswith("does <b>not</b> meet") and f"{100 * bad:.3g} %" in text


def test_a_change_is_called_a_cut_only_when_it_is_lower():
    assert change_text("the error", 0.01, 0.3, "before").startswith("cuts the error to 1 %")
    assert change_text("the error", 0.3, 0.01, "before").startswith("does not cut the error")
    assert change_text("the error", 0.1, 0.1, "before").startswith("leaves the error at")
    assert "-" in change_text("the error", np.inf, 0.1, "before")


def _run(w, a1, a2, ja1, ja2, n=2048):
    phi = w * np.arange(n) / 1000.0
    return pd.DataFrame({"phi": phi, "xO1": a1 * np.cos(phi) + a2 * np.cos(2 * phi + 0.3),
                         "xA": ja1 * np.cos(phi) + ja2 * np.cos(2 * phi)})


def test_the_harmonic_sentence_reads_the_simulated_orders():
    runs = {94.2: _run(94.2, 1e-4, 1e-8, 1e-5, 1e-8), 250.0: _run(250.0, 1e-4, 3e-8, 1e-5, 4e-8)}
    text = harmonics_text(runs)
    assert text.startswith("1x dominates at every figure speed (94.2, 250 rad/s)")
    assert "1.0e-04 to 3.0e-04 of the 1x at the disk" in text
    assert "1.0e-03 to 4.0e-03 at the journal" in text and "stronger at the journal" in text
    text = harmonics_text({100.0: _run(100.0, 1e-6, 2e-6, 1e-5, 1e-8)})
    assert text.startswith("1x does not dominate everywhere") and "stronger at the disk" in text


def test_percentages_are_never_rounded_up_to_a_whole_they_are_short_of():
    assert aerr_text(99.99999988) == "99.9999999 %"  # the "100.000000 %"
    assert percentage(99.96, 1) == "99.96 %" and percentage(100.0, 1) == "100.0 %"
    assert percentage(12.34) == "12.3 %"


def test_a_panel_of_tiny_coefficients_carries_its_power_in_the_title_not_an_offset():
    """The issue's collision: matplotlib's '1e-8' offset label sat on the panel title."""
    import matplotlib

    matplotlib.use("Agg")
    from sknarx.plotting import plt
    from sknarx.reproduce.figures import _scaled_title

    fig, (a, b) = plt.subplots(1, 2)
    values = np.array([-5.4e-8, -2.9e-8, -4.0e-8])
    a.plot(values)
    assert _scaled_title(a, "u(t-3)", values) == -8
    fig.canvas.draw()
    assert a.get_title() == "u(t-3)  (x 1e-8)"
    assert a.yaxis.get_offset_text().get_text() == ""
    assert all("e" not in t.get_text() for t in a.get_yticklabels())
    b.plot([2.3, 2.8])
    assert _scaled_title(b, "y(t-1)", np.array([2.3, 2.8])) == 0 and b.get_title() == "y(t-1)"
    plt.close(fig)
