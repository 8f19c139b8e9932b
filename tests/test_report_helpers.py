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


def test_a_table_of_model_terms_keeps_each_term_on_one_line():
    from sknarx._report import CSS, table

    html = table([["y(t-1)*u(t-2)*u(t-3)", "1e-10"]], ["term", "coef"], nowrap=True)
    assert html.startswith('<table class="nowrap">')
    assert "table.nowrap td{white-space:nowrap}" in CSS
    assert table([["a"]], ["h"]).startswith("<table><tr>")


def test_a_legend_below_the_axes_covers_no_data(tmp_path):
    """The issue's legends sat on the traces (RK-4 polar plot, fig9): a figure legend
    laid out below every axes, for one row of entries and for several."""
    from sknarx.plotting import legend_below, plt, save

    for n_lines, ncol in ((3, 3), (7, 2)):
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(5, 4))
        for k in range(n_lines):
            a1.plot([0, 1], [k, k + 1], label=f"trace {k}")
        a2.plot([0, 1], [1, 0])
        save(fig, tmp_path / "f.png", rect=legend_below(fig, a1, ncol=ncol))
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        renderer = FigureCanvasAgg(fig).get_renderer()
        legend = fig.legends[0].get_window_extent(renderer)
        for ax in (a1, a2):
            box = ax.get_tightbbox(renderer)
            assert legend.y1 <= box.y0 + 1, (n_lines, ncol)
        assert legend.y0 >= 0
