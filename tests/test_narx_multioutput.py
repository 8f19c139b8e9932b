"""Multi-input, multi-output models: joint lags, joint free run and its sensitivities,
output-error refinement, JSON, summary, Pipeline."""

import numpy as np
import pandas as pd
import pytest

from sknarx import MultiOutputScheduledNarx
from sknarx.narx._joint_output_error import _joint_sens
from sknarx.narx.freerun import free_run_mimo, term_factors
from sknarx.narx.terms import channel_counts, monomial_exponents, parse_terms, term_names


def _coupled(n, seed, speed=0.0, noise=0.0):
    """Two coupled outputs driven by two inputs; the first output's damping moves with
    the speed (rad/s). ``noise`` is added to the measured outputs only."""
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((n, 2))
    Y = np.zeros((n, 2))
    for t in range(2, n):
        Y[t, 0] = ((0.5 + 0.001 * speed) * Y[t - 1, 0] - 0.2 * Y[t - 2, 0]
                   + 0.2 * Y[t - 1, 1] + U[t - 1, 0])
        Y[t, 1] = 0.4 * Y[t - 1, 1] + U[t - 1, 1] + 0.1 * Y[t - 1, 0] ** 2
    return U, Y + noise * rng.standard_normal((n, 2))


def test_multi_channel_names_parse_back_and_single_channels_keep_the_plain_names():
    ex = monomial_exponents(2, 1, 2, n_outputs=2, n_inputs=2)
    names = term_names(ex, 2, 1, 2, 2)
    assert "y2(t-2)*u1(t-1)" in names and channel_counts(names) == (2, 2)
    back, ny, nu = parse_terms(names)
    np.testing.assert_array_equal(back, ex)
    assert (ny, nu) == (2, 1)
    assert term_names(monomial_exponents(2, 1, 2), 2, 1)[:4] == [
        "1", "y(t-1)", "y(t-2)", "u(t-1)"]


def test_joint_sensitivities_are_the_derivatives_of_the_joint_free_run():
    U, Y = _coupled(300, 0)
    names = ["y1(t-1)", "y2(t-1)", "u1(t-1)", "y1(t-1)*y2(t-2)",
             "y2(t-1)", "u2(t-1)", "y1(t-1)^2", "y2(t-2)*u1(t-2)"]
    owner = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    ex, ny, nu = parse_terms(names, 2, 2)
    theta = np.array([0.5, 0.2, 1.0, 0.01, 0.4, 1.0, 0.1, 0.02])
    start = max(ny, nu)
    Ys = np.zeros_like(Y)
    Ys[:start] = Y[:start]
    S = np.zeros((len(Y), 2, theta.size))
    assert _joint_sens(U, Ys, theta, term_factors(ex), owner, ny, nu, start, S) == -1
    ref, _ = free_run_mimo(U, theta[None], ex, owner, ny, nu, 2, Y0=Y[:start])
    np.testing.assert_allclose(Ys, ref, atol=1e-12)
    for k in range(theta.size):
        h = 1e-6
        up, dn = theta.copy(), theta.copy()
        up[k] += h
        dn[k] -= h
        fd = (free_run_mimo(U, up[None], ex, owner, ny, nu, 2, Y0=Y[:start])[0]
              - free_run_mimo(U, dn[None], ex, owner, ny, nu, 2, Y0=Y[:start])[0]) / (2 * h)
        np.testing.assert_allclose(S[:, :, k], fd, atol=1e-6 * np.abs(fd).max())


def test_a_coupled_system_is_identified_per_output_and_free_runs_jointly_at_new_speeds():
    speeds = np.array([50.0, 100.0, 150.0, 200.0])
    data = [_coupled(800, k, speed=w) for k, w in enumerate(speeds)]
    m = MultiOutputScheduledNarx(ny=2, nu=1, degree=2, max_terms=4, esr=1e-8,
                                 coef_degree=1).fit(data, speeds)
    assert sorted(m.selected_terms_[0]) == ["u1(t-1)", "y1(t-1)", "y1(t-2)", "y2(t-1)"]
    assert sorted(m.selected_terms_[1]) == ["u2(t-1)", "y1(t-1)^2", "y2(t-1)"]
    U, Y = _coupled(600, 99, speed=125.0)
    np.testing.assert_allclose(m.simulate(U, 125.0, Y0=Y[:2]), Y, atol=1e-8)
    with pytest.raises(ValueError, match="give the speed omega"):
        m.simulate(U)


def test_joint_output_error_refinement_removes_the_bias_of_least_squares():
    data = [_coupled(3000, 1, noise=0.3)]
    kw = dict(ny=2, nu=1, degree=2, max_terms=4, esr=0)
    ls = MultiOutputScheduledNarx(**kw).fit(data)
    oe = MultiOutputScheduledNarx(**kw, refine="output_error").fit(data)
    assert oe.selected_terms_ == ls.selected_terms_
    i = oe.selected_terms_[0].index("y1(t-1)")
    e_ls = abs(ls.estimators_[0].coef_per_speed_.iloc[0, i] - 0.5)
    e_oe = abs(oe.estimators_[0].coef_per_speed_.iloc[0, i] - 0.5)
    se = oe.estimators_[0].coef_std_err_per_speed_.iloc[0, i]
    assert e_oe < 0.3 * e_ls and e_oe < 4 * se


def test_joint_speed_functions_refined_and_kept_with_their_covariance():
    speeds = np.array([50.0, 100.0, 150.0, 200.0])
    data = [_coupled(1500, k, speed=w, noise=0.2) for k, w in enumerate(speeds)]
    kw = dict(ny=2, nu=1, degree=2, max_terms=4, esr=0, coef_degree=1)
    oe = MultiOutputScheduledNarx(**kw, refine="output_error").fit(data, speeds)
    first = oe.estimators_[0]
    slope = first.speed_polynomials_.loc["y1(t-1)", "beta1"]
    se = first.speed_polynomials_std_err_.loc["y1(t-1)", "beta1"]
    assert first.coef_poly_cov_ is not None and abs(slope - 0.001) < 4 * se
    back = MultiOutputScheduledNarx.from_json(oe.to_json())
    U, Y = _coupled(400, 7, speed=120.0)
    np.testing.assert_array_equal(back.simulate(U, 120.0, Y0=Y[:2]),
                                  oe.simulate(U, 120.0, Y0=Y[:2]))
    table = oe.summary()
    assert set(table.output) == {1, 2} and {"term", "coef", "std_err"} <= set(table.columns)


def test_simulation_error_selection_of_a_joint_structure():
    data = [_coupled(600, 3)]
    m = MultiOutputScheduledNarx(ny=2, nu=1, degree=2, selection="simulation").fit(data)
    assert sorted(m.selected_terms_[0]) == ["u1(t-1)", "y1(t-1)", "y1(t-2)", "y2(t-1)"]
    assert sorted(m.selected_terms_[1]) == ["u2(t-1)", "y1(t-1)^2", "y2(t-1)"]


def test_in_a_pipeline_with_a_table_and_cross_validation_over_speeds():
    from sklearn.model_selection import cross_validate
    from sklearn.pipeline import make_pipeline

    from sknarx import LeaveOneSpeedOut

    speeds = np.array([50.0, 100.0, 150.0, 200.0, 250.0])
    frames, outs = [], []
    for k, w in enumerate(speeds):
        U, Y = _coupled(500, k, speed=w)
        frames.append(pd.DataFrame({"speed": w, "u1": U[:, 0], "u2": U[:, 1]}))
        outs.append(Y)
    X, Y = pd.concat(frames, ignore_index=True), np.vstack(outs)
    pipe = make_pipeline(MultiOutputScheduledNarx(ny=2, nu=1, degree=2, max_terms=4, esr=0,
                                                  coef_degree=1))
    scores = cross_validate(pipe, X, Y, groups=X["speed"], cv=LeaveOneSpeedOut())
    assert np.all(scores["test_score"] > 0.99)
    assert pipe.fit(X, Y).predict(X).shape == Y.shape


def test_records_that_disagree_on_their_channels_are_refused_by_name():
    U, Y = _coupled(300, 0)
    with pytest.raises(ValueError, match="same channels"):
        MultiOutputScheduledNarx(ny=1, nu=1, degree=1).fit([(U, Y), (U[:, :1], Y)])
