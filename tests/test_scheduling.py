import json
import warnings

import numpy as np
import pandas as pd
import pytest
from narx_systems import simulate_system
from sklearn.base import clone
from sklearn.model_selection import GridSearchCV, LeaveOneGroupOut, cross_validate
from sklearn.pipeline import make_pipeline

from sknarx import (
    CommonStructureEFOR,
    FreeRunDivergenceError,
    NarxTermDictionary,
    SpeedExtrapolationWarning,
    SpeedScheduledNarx,
    free_run_scorer,
    model_from_json,
)

TERMS = ["y(t-1)", "y(t-2)", "u(t-1)", "u(t-2)^2", "y(t-1)*u(t-1)", "1"]
SPEEDS = np.linspace(80.0, 280.0, 7)


def coef_fn(w):
    s = (w - 180.0) / 100.0
    return [0.5 + 0.2 * s, -0.2, 1.0 + 0.3 * s**2, 0.2 - 0.1 * s, 0.05 * s, 0.02]


@pytest.fixture(scope="module")
def sweep():
    data = simulate_system(TERMS, coef_fn, SPEEDS, n=500, seed=1)
    df = pd.concat(
        [pd.DataFrame({"speed": w, "u": u, "y": y}) for (u, y), w in zip(data, SPEEDS,
                                                                       strict=True)],
        ignore_index=True,
    )
    return data, df


def make_pipe(**kw):
    return make_pipeline(
        NarxTermDictionary(ny=2, nu=2, degree=3),
        CommonStructureEFOR(esr=kw.get("esr", 1e-9)),
        SpeedScheduledNarx(coef_degree=kw.get("coef_degree", 2)),
    )


def test_direct_fit_recovers_terms_and_tables(sweep):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(data, SPEEDS)
    assert sorted(m.selected_terms_) == sorted(TERMS)
    assert m.coef_per_speed_.shape == (7, 6)
    assert list(m.speed_polynomials_.columns) == ["beta0", "beta1", "beta2"]
    # Table-4 form (raw powers of omega) reproduces the scaled evaluation
    w = 137.0
    raw = m.speed_polynomials_.to_numpy() @ (w ** np.arange(3))
    np.testing.assert_allclose(raw, m.coefficients_at(w), rtol=1e-9)


def test_long_dataframe_equals_list_of_pairs(sweep):
    data, df = sweep
    a = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(data, SPEEDS)
    b = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(df)
    assert a.selected_terms_ == b.selected_terms_
    np.testing.assert_array_equal(a.coef_poly_, b.coef_poly_)


def test_pipeline_matches_direct_api_and_free_runs_at_new_speed(sweep):
    data, df = sweep
    direct = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(data, SPEEDS)
    pipe = make_pipe().fit(df[["speed", "u", "y"]], df["y"])
    model = pipe[-1]
    assert model.selected_terms_ == direct.selected_terms_
    a, b = model.coef_per_speed_.to_numpy(), direct.coef_per_speed_.to_numpy()
    assert np.max(np.abs(a - b)) <= 1e-10 * np.max(np.abs(b))
    # free run at a speed never seen in training
    w_new = 173.3
    rng = np.random.default_rng(9)
    u = rng.uniform(-1, 1, 400)
    truth = simulate_system(TERMS, coef_fn, [w_new], n=400, seed=9)[0][1]
    yhat = model.simulate(u, w_new)
    assert np.max(np.abs(yhat - truth)) < 1e-6 * np.max(np.abs(truth))


def test_cross_validation_over_held_out_speeds(sweep):
    _, df = sweep
    inner = df[(df.speed > 80) & (df.speed < 280)]
    X, y = inner[["speed", "u", "y"]], inner["y"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SpeedExtrapolationWarning)
        res = cross_validate(make_pipe(), X, y, groups=X["speed"], cv=LeaveOneGroupOut(),
                             scoring=free_run_scorer)
    assert len(res["test_score"]) == 5
    # noise-free, exact structure: held-out speeds are predicted almost perfectly
    assert np.all(res["test_score"] > -1e-6)


def test_grid_search_over_degree_esr_and_coef_degree(sweep):
    _, df = sweep
    X, y = df[["speed", "u", "y"]], df["y"]
    grid = {
        "narxtermdictionary__degree": [1, 3],
        "commonstructureefor__esr": [5.0, 1e-9],
        "speedschedulednarx__coef_degree": [1, 2],
    }
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gs = GridSearchCV(make_pipe(), grid, cv=LeaveOneGroupOut(), scoring=free_run_scorer)
        gs.fit(X, y, groups=X["speed"])
    assert gs.best_params_["narxtermdictionary__degree"] == 3
    assert gs.best_params_["commonstructureefor__esr"] == 1e-9
    assert gs.best_params_["speedschedulednarx__coef_degree"] == 2
    assert gs.best_score_ > -1e-6


def test_clone_and_params_are_verbatim():
    m = SpeedScheduledNarx(ny=2, nu=1, degree=2, esr=0.5, max_terms=4, coef_degree=1)
    c = clone(m)
    assert c.get_params() == m.get_params()
    pipe = clone(make_pipe())
    assert pipe.get_params()["speedschedulednarx__coef_degree"] == 2


def test_fit_does_not_mutate_parameters(sweep):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2)
    before = m.get_params()
    m.fit(data, SPEEDS)
    assert m.get_params() == before


def test_json_round_trip_is_exact(sweep, tmp_path):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(data, SPEEDS)
    path = tmp_path / "model.json"
    m.to_json(path)
    doc = json.loads(path.read_text())
    assert doc["sknarx_version"] and doc["selected_terms"] == m.selected_terms_
    m2 = model_from_json(path)
    np.testing.assert_array_equal(m2.coef_poly_, m.coef_poly_)
    np.testing.assert_array_equal(m2.coef_per_speed_.to_numpy(), m.coef_per_speed_.to_numpy())
    u = np.random.default_rng(0).uniform(-1, 1, 300)
    np.testing.assert_array_equal(m2.simulate(u, 190.0), m.simulate(u, 190.0))
    assert m2.get_params() == m.get_params()
    assert SpeedScheduledNarx.from_json(m.to_json()).selected_terms_ == m.selected_terms_


def test_run_up_omega_array_and_initial_conditions(sweep):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(data, SPEEDS)
    u = np.random.default_rng(2).uniform(-1, 1, 600)
    omega = np.linspace(90, 270, 600)
    y = m.simulate(u, omega)
    # the same recursion with time-varying true coefficients
    from sknarx.narx.freerun import free_run
    from sknarx.narx.terms import parse_terms

    exps, ny, nu = parse_terms(TERMS)
    truth, _ = free_run(u, np.array([coef_fn(w) for w in omega]), exps, ny, nu)
    np.testing.assert_allclose(y, truth, atol=1e-8 * np.abs(truth).max())
    y2 = m.simulate(u, omega, y0=[0.3, -0.1])
    assert y2[0] == 0.3 and y2[1] == -0.1
    with pytest.raises(ValueError, match="one value per sample"):
        m.simulate(u, omega[:10])


def test_out_of_range_speed_warns_and_divergence_is_reported(sweep):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2).fit(data, SPEEDS)
    u = np.random.default_rng(3).uniform(-1, 1, 200)
    with pytest.warns(SpeedExtrapolationWarning, match="outside the fitted range"):
        m.simulate(u, 300.0)
    # A huge input drives the bilinear term y*u past stability
    with pytest.raises(FreeRunDivergenceError, match="diverged at sample"):
        m.simulate(500 * u, 200.0)
    with pytest.warns(RuntimeWarning, match="diverged"):
        y = m.simulate(500 * u, 200.0, on_divergence="warn")
    assert np.isnan(y[-1])


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: [(np.r_[d[0][0][:-1], np.nan], d[0][1])] + d[1:], "NaN/inf"),
        (lambda d: [(d[0][0], np.r_[d[0][1][:-1], np.inf])] + d[1:], "NaN/inf"),
        (lambda d: [(d[0][0][:-3], d[0][1])] + d[1:], "samples but y has"),
        (lambda d: [(d[0][0][:3], d[0][1][:3])] + d[1:], "too few"),
        (lambda d: [(np.zeros_like(d[0][0]), d[0][1])] + d[1:], "constant"),
        (lambda d: [(np.full_like(d[0][0], 2.0), d[0][1])] + d[1:], "constant"),
    ],
)
def test_bad_input_names_the_problem(sweep, mutate, match):
    data, _ = sweep
    with pytest.raises(ValueError, match=match):
        SpeedScheduledNarx(ny=2, nu=2, degree=3, coef_degree=2).fit(mutate(list(data)), SPEEDS)


def test_bad_speeds(sweep):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, coef_degree=3)
    with pytest.raises(ValueError, match="at least 4 distinct speeds"):
        m.fit(data[:3], SPEEDS[:3])
    with pytest.raises(ValueError, match="one speed per dataset"):
        m.fit(data, SPEEDS[:3])
    with pytest.raises(ValueError, match="finite"):
        m.fit(data[:5], np.r_[SPEEDS[:4], np.nan])


def test_spline_speed_basis_interpolates_per_speed_coefficients_and_round_trips(sweep):
    data, _ = sweep
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9,
                           speed_basis="spline").fit(data, SPEEDS)
    with pytest.warns(UserWarning, match="does not change a speed_basis='spline'"):
        SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2,
                           speed_basis="spline").fit(data, SPEEDS)
    np.testing.assert_allclose(m.coefficients_at(SPEEDS), m.coef_per_speed_.to_numpy(),
                               rtol=1e-12, atol=1e-15)
    m2 = model_from_json(m.to_json())
    w = np.linspace(85, 275, 7)
    np.testing.assert_array_equal(m2.coefficients_at(w), m.coefficients_at(w))
    with pytest.raises(ValueError, match="at least 3"):
        SpeedScheduledNarx(ny=1, nu=1, degree=1, speed_basis="spline").fit(data[:2], SPEEDS[:2])
