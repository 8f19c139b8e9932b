from math import factorial

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx import NarxTermDictionary
from sknarx.narx.terms import (
    TermSet,
    monomial_exponents,
    n_candidate_terms,
    parse_terms,
    term_names,
)


@given(st.integers(0, 4), st.integers(0, 4), st.integers(0, 4))
def test_term_count_formula(ny, nu, degree):
    n = ny + nu
    expected = factorial(n + degree) // (factorial(n) * factorial(degree))
    exps = monomial_exponents(ny, nu, degree)
    assert exps.shape == (expected, n)
    assert n_candidate_terms(ny, nu, degree) == expected
    # all distinct, all within the degree
    assert len({tuple(r) for r in exps}) == expected
    assert exps.sum(axis=1).max(initial=0) <= degree


def test_paper_dictionary_has_84_terms():
    assert n_candidate_terms(3, 3, 3) == 84


def test_name_format():
    names = term_names(monomial_exponents(3, 3, 3), 3, 3)
    assert names[0] == "1"
    for n in ["y(t-1)", "u(t-2)^2", "y(t-1)*u(t-3)", "y(t-1)^2*u(t-2)", "u(t-1)*u(t-2)*u(t-3)"]:
        assert n in names
    # y factors before u factors, lags ascending
    assert "u(t-3)*y(t-1)" not in names
    assert "u(t-2)*u(t-1)" not in names


@given(st.integers(0, 3), st.integers(0, 3), st.integers(0, 3))
def test_names_round_trip(ny, nu, degree):
    exps = monomial_exponents(ny, nu, degree)
    names = term_names(exps, ny, nu)
    back, ny2, nu2 = parse_terms(names)
    # parse_terms returns the narrowest matrix; re-embed for comparison
    full = np.zeros_like(exps)
    full[:, :ny2] = back[:, :ny2]
    full[:, ny : ny + nu2] = back[:, ny2:]
    np.testing.assert_array_equal(full, exps)


def test_parse_rejects_garbage():
    with pytest.raises(ValueError, match="Cannot parse"):
        parse_terms(["y(t-1)", "sin(u)"])


def test_termset_values_match_direct_products():
    rng = np.random.default_rng(3)
    u, y = rng.standard_normal(40), rng.standard_normal(40)
    exps = monomial_exponents(2, 3, 3)
    P = TermSet(exps, 2, 3).evaluate(u, y, 3, 40)
    lag = np.column_stack([y[2:39], y[1:38], u[2:39], u[1:38], u[0:37]])
    expected = np.prod(lag[:, None, :] ** exps[None, :, :], axis=2)
    np.testing.assert_allclose(P, expected, rtol=1e-13)


def test_dictionary_transform_marks_history_rows_and_speed_index():
    import pandas as pd

    rng = np.random.default_rng(0)
    df = pd.DataFrame(
        {"speed": np.repeat([100.0, 200.0], 20), "u": rng.standard_normal(40),
         "y": rng.standard_normal(40)}
    )
    d = NarxTermDictionary(ny=2, nu=3, degree=2).fit(df)
    P = d.transform(df)
    assert P.index.name == "speed"
    assert list(P.columns) == list(d.get_feature_names_out())
    nan_rows = P.isna().all(axis=1).to_numpy()
    assert nan_rows.sum() == 6  # max lag 3, two datasets
    assert nan_rows[[0, 1, 2, 20, 21, 22]].all()
    assert not P.iloc[~nan_rows].isna().any().any()
    assert d.exponents_.shape == (d.n_terms_, 5)
