"""Uncertainty, model validity tests, NARMAX (extended least squares) and the results table."""

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from sklearn.pipeline import make_pipeline

from sknarx import CommonStructureEFOR, NarxTermDictionary, SpeedScheduledNarx
from sknarx.narx._orthogonal import coef_covariance, compress, efor, matrix_blocks, unscale
from sknarx.narx.validity import correlation_tests, one_step_residuals, validity_summary

SPEEDS = np.array([100.0, 150.0, 200.0, 250.0])


def narmax_data(speeds, n=3000, c=0.0, noise=0.05, quad=0.4, seed=0):
    """``y = (0.3 + 1e-3 w) y(t-1) + u(t-1) + quad u(t-1)^2 + e(t) + c e(t-1)``."""
    rng = np.random.default_rng(seed)
    data = []
    for w in speeds:
        u = rng.uniform(-1, 1, n)
        e = noise * rng.standard_normal(n)
        y = np.zeros(n)
        a = 0.3 + 1e-3 * w
        for t in range(1, n):
            y[t] = a * y[t - 1] + u[t - 1] + quad * u[t - 1] ** 2 + e[t] + c * e[t - 1]
        data.append((u, y))
    return data


def arx_data(speeds, n, rng, noise=0.2):
    """``y = (0.2 + 2e-3 w) y(t-1) + (1 - 1e-3 w) u(t-1) + e``, white noise."""
    data = []
    for w in speeds:
        u = rng.uniform(-1, 1, n)
        e = noise * rng.standard_normal(n)
        y = np.zeros(n)
        for t in range(1, n):
            y[t] = (0.2 + 2e-3 * w) * y[t - 1] + (1 - 1e-3 * w) * u[t - 1] + e[t]
        data.append((u, y))
    return data


def truth(w):
    return {"u(t-1)": 1 - 1e-3 * w, "y(t-1)": 0.2 + 2e-3 * w}


# ------------------------------------------------------------------ covariance
@given(seed=st.integers(0, 10_000), solver=st.sampled_from(["gram", "qr"]),
       scale=st.floats(1e-6, 1e3))
def test_covariance_equals_direct_least_squares(seed, solver, scale):
    rng = np.random.default_rng(seed)
    Zs, norms, raw = [], [], []
    for _ in range(3):
        P = rng.standard_normal((300, 4)) * np.array([1.0, 10.0, 0.1, 3.0]) * scale
        y = P @ np.array([1.0, 2.0, 3.0, 0.5]) + 0.3 * scale * rng.standard_normal(300)
        Z, nrm = compress(matrix_blocks(P, y), 5, solver)
        Zs.append(Z)
        norms.append(nrm)
        raw.append((P, y))
    norms = np.stack(norms)
    res = efor(np.stack(Zs), norms, max_terms=4)
    coef = unscale(res.coef, norms, res.selected)
    cov, sigma2, dof = coef_covariance(res, norms, [300] * 3)
    for k, (P, y) in enumerate(raw):
        Ps = P[:, res.selected]
        theta, *_ = np.linalg.lstsq(Ps, y, rcond=None)
        r = y - Ps @ theta
        s2 = r @ r / (300 - 4)
        C = s2 * np.linalg.inv(Ps.T @ Ps)
        np.testing.assert_allclose(coef[k], theta, rtol=1e-8)
        np.testing.assert_allclose(sigma2[k], s2, rtol=1e-6)
        sd = np.sqrt(np.diag(C))
        np.testing.assert_allclose(cov[k] / np.outer(sd, sd), C / np.outer(sd, sd), atol=1e-6)
        assert dof[k] == 296


def test_standard_errors_cover_the_truth_at_the_nominal_rate():
    """Over 200 noisy draws, 95 % intervals of the per-speed coefficients and of the
    speed function at an unseen speed cover the truth 90-99 % of the time."""
    rng = np.random.default_rng(20261122)
    speeds = np.array([80.0, 140.0, 200.0])
    hit_speed, hit_fn, n_speed, n_fn = 0, 0, 0, 0
    for _ in range(200):
        data = arx_data(speeds, 300, rng)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            m = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, esr=0,
                                   coef_degree=1).fit(data, speeds)
        assert sorted(m.selected_terms_) == ["u(t-1)", "y(t-1)"]
        for w in speeds:
            for term, value in truth(w).items():
                est = m.coef_per_speed_.loc[w, term]
                se = m.coef_std_err_per_speed_.loc[w, term]
                hit_speed += abs(est - value) <= 1.96 * se
                n_speed += 1
        theta, std = m.coefficients_at(170.0, return_std=True)
        for j, term in enumerate(m.selected_terms_):
            hit_fn += abs(theta[j] - truth(170.0)[term]) <= 1.96 * std[j]
            n_fn += 1
    assert 0.90 <= hit_speed / n_speed <= 0.99, hit_speed / n_speed
    assert 0.90 <= hit_fn / n_fn <= 0.99, hit_fn / n_fn


def test_speed_function_errors_propagate_through_both_bases():
    data = arx_data(SPEEDS, 600, np.random.default_rng(3))
    for basis in ("polynomial", "spline"):
        m = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, esr=0,
                               coef_degree=1 if basis == "polynomial" else None,
                               speed_basis=basis).fit(data, SPEEDS)
        theta, std = m.coefficients_at(SPEEDS, return_std=True)
        assert std.shape == theta.shape and np.all(std > 0)
        if basis == "spline":  # the spline interpolates: at a knot, the knot's own error
            np.testing.assert_allclose(std, m.coef_std_err_per_speed_.to_numpy(), rtol=1e-9)
        else:  # a least-squares line through 4 points is surer than any one of them
            assert np.all(std < m.coef_std_err_per_speed_.to_numpy())
        fn = m.summary(kind="speed_function")
        assert list(fn.columns) == ["term", "parameter", "value", "std_err"]
        assert np.all(np.isfinite(fn["std_err"])) and np.all(fn["std_err"] > 0)
        boot = m.bootstrap_speed_function(n_resamples=50, random_state=0)
        assert boot.shape == fn.shape and np.all(boot["std_err"] > 0)
        pd.testing.assert_frame_equal(boot.drop(columns="std_err"),
                                      fn.drop(columns="std_err"))


def test_summary_has_one_row_per_speed_and_term():
    data = narmax_data(SPEEDS, n=1500)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1)
    m.fit(data, SPEEDS)
    table = m.summary()
    for col in ("speed", "term", "coef", "std_err", "aerr"):
        assert col in table.columns
    assert len(table) == len(SPEEDS) * len(m.selected_terms_)
    row = table[(table.speed == 150.0) & (table.term == "y(t-1)")].iloc[0]
    assert row.coef == m.coef_per_speed_.loc[150.0, "y(t-1)"]
    assert row.std_err == m.coef_std_err_per_speed_.loc[150.0, "y(t-1)"]
    with pytest.raises(ValueError, match="kind must be"):
        m.summary(kind="bogus")


def test_json_keeps_the_uncertainty_and_reads_format_1():
    data = narmax_data(SPEEDS, n=1500, c=0.7, seed=4)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1,
                           noise_lags=2).fit(data, SPEEDS)
    back = SpeedScheduledNarx.from_json(m.to_json())
    pd.testing.assert_frame_equal(back.summary(), m.summary())
    pd.testing.assert_frame_equal(back.summary("speed_function"), m.summary("speed_function"))
    assert back.noise_terms_ == m.noise_terms_ == ["e(t-1)"]
    np.testing.assert_array_equal(back.simulate(data[0][0], 120.0), m.simulate(data[0][0], 120.0))
    doc = json.loads(m.to_json())
    for key in ("coef_cov_per_speed", "coef_std_err_per_speed", "noise_variance_per_speed",
                "dof_per_speed", "speed_polynomial_raw_std_err", "noise_terms", "n_iter"):
        doc.pop(key)
    doc["format_version"] = 1
    old = SpeedScheduledNarx.from_json(json.dumps(doc))
    np.testing.assert_array_equal(old.coefficients_at(120.0), m.coefficients_at(120.0))
    with pytest.raises(ValueError, match="format-1"):
        old.coefficients_at(120.0, return_std=True)


# ------------------------------------------------------------ prediction bands
def test_simulate_interval_brackets_the_run_and_counts_divergence():
    data = narmax_data(SPEEDS, n=1500, seed=5)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1)
    m.fit(data, SPEEDS)
    u = np.random.default_rng(9).uniform(-1, 1, 400)
    band = m.simulate_interval(u, 175.0, n_draws=100, random_state=0)
    again = m.simulate_interval(u, 175.0, n_draws=100, random_state=0)
    np.testing.assert_array_equal(band.lower, again.lower)
    assert band.diverged_fraction == 0.0
    assert np.all(band.lower[1:] < band.upper[1:])
    inside = (band.lower <= band.y) & (band.y <= band.upper)
    assert inside[1:].mean() > 0.99
    ramp = np.linspace(100.0, 250.0, u.size)  # a run-up through the fitted range
    assert np.all(np.isfinite(m.simulate_interval(u, ramp, n_draws=20, random_state=1).upper))

    # a short record of a slow system: y(t-1) near 0.9 with a standard error of ~0.06,
    # so a few percent of the coefficient draws are unstable
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1, 80)
    y = np.zeros(80)
    for t in range(1, 80):
        y[t] = 0.98 * y[t - 1] + 0.05 * x[t - 1] + 0.05 * rng.standard_normal()
    m_edge = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, esr=0, coef_degree=0)
    m_edge.fit([(x, y)], [150.0])
    far = m_edge.simulate_interval(np.ones(5000), 150.0, n_draws=200, random_state=0)
    assert 0.0 < far.diverged_fraction < 0.2
    assert np.all(np.isfinite(far.upper))


# ------------------------------------------------------------- validity tests
def _passed(model, data, speeds, scope="pooled"):
    summary = validity_summary(correlation_tests(model, data, speeds))
    return summary[summary.scope == scope].set_index("test")["passed"]


def test_validity_tests_pass_the_true_model_and_flag_an_underparametrised_one():
    data = narmax_data(SPEEDS, seed=11)
    true = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1)
    true.fit(data, SPEEDS)
    assert sorted(true.selected_terms_) == ["u(t-1)", "u(t-1)^2", "y(t-1)"]
    assert _passed(true, data, SPEEDS).all()
    assert _passed(true, data, SPEEDS, scope="per_speed").all()
    under = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=3, esr=0, coef_degree=1)
    under.fit(data, SPEEDS)  # cannot express u(t-1)^2
    verdict = _passed(under, data, SPEEDS)
    assert not verdict["phi_u2_e"] and not verdict["phi_u2_e2"]


def test_validity_tests_flag_coloured_noise_and_narmax_removes_it():
    data = narmax_data(SPEEDS, c=0.8, seed=12)
    narx = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1)
    assert not _passed(narx.fit(data, SPEEDS), data, SPEEDS)["phi_ee"]
    narmax = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1,
                                noise_lags=2).fit(data, SPEEDS)
    assert narmax.noise_terms_ == ["e(t-1)"]
    assert _passed(narmax, data, SPEEDS).all()


def test_table_layout_and_residuals():
    data = narmax_data(SPEEDS[:2], n=800)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1)
    m.fit(data, SPEEDS[:2])
    table = correlation_tests(m, data, SPEEDS[:2], max_lag=5)
    assert set(table.test) == {"phi_ee", "phi_ue", "phi_e_eu", "phi_u2_e", "phi_u2_e2"}
    assert set(table.scope) == {"per_speed", "pooled"}
    assert len(table[(table.scope == "pooled") & (table.test == "phi_ue")]) == 11
    assert np.all(np.abs(table.value) <= 1 + 1e-12)
    e = one_step_residuals(m, *data[0], SPEEDS[0])
    assert e.shape == (799,)
    long = pd.concat([pd.DataFrame({"speed": w, "u": u, "y": y})
                      for w, (u, y) in zip(SPEEDS[:2], data, strict=True)])
    pd.testing.assert_frame_equal(correlation_tests(m, long, max_lag=5), table)
    with pytest.raises(ValueError, match="too few"):
        correlation_tests(m, [(u[:20], y[:20]) for u, y in data], SPEEDS[:2], max_lag=15)


# -------------------------------------------------------------------- NARMAX
@given(seed=st.integers(0, 10_000), noise=st.floats(0.01, 0.3))
def test_white_noise_selects_no_noise_terms(seed, noise):
    data = narmax_data(SPEEDS[:3], n=1500, noise=noise, seed=seed)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1,
                           noise_lags=3).fit(data, SPEEDS[:3])
    assert m.noise_terms_ == []
    plain = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0,
                               coef_degree=1).fit(data, SPEEDS[:3])
    np.testing.assert_allclose(m.coef_per_speed_, plain.coef_per_speed_, rtol=1e-9)


@given(seed=st.integers(0, 10_000), c=st.floats(0.5, 0.9))
def test_ma_noise_process_coefficients_are_unbiased_within_their_errors(seed, c):
    data = narmax_data(SPEEDS[:3], n=3000, c=c, noise=0.1, seed=seed)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1,
                           noise_lags=2).fit(data, SPEEDS[:3])
    assert "e(t-1)" in m.noise_terms_
    table = m.summary()
    row = table[table.term == "y(t-1)"]
    z = (row.coef - (0.3 + 1e-3 * row.speed)) / row.std_err
    assert np.all(np.abs(z) < 4.0), z.tolist()
    ma = table[table.term == "e(t-1)"]
    assert np.all(np.abs(ma.coef - c) < 4.0 * ma.std_err)


def test_narx_least_squares_is_biased_by_ma_noise():
    """The premise of the noise model, on the data the property above uses."""
    data = narmax_data(SPEEDS[:3], n=3000, c=0.8, noise=0.1, seed=1)
    m = SpeedScheduledNarx(ny=1, nu=1, degree=2, max_terms=3, esr=0,
                           coef_degree=1).fit(data, SPEEDS[:3])
    row = m.summary().query("term == 'y(t-1)'")
    assert np.all((row.coef - (0.3 + 1e-3 * row.speed)) / row.std_err > 4.0)


def test_narmax_in_a_pipeline():
    data = narmax_data(SPEEDS, n=3000, c=0.8, noise=0.1, seed=2)
    X = pd.concat([pd.DataFrame({"speed": w, "u": u, "y": y})
                   for w, (u, y) in zip(SPEEDS, data, strict=True)], ignore_index=True)
    d = NarxTermDictionary(ny=1, nu=1, degree=2, noise_lags=2)
    assert list(d.fit(X).get_feature_names_out()[-2:]) == ["e(t-1)", "e(t-2)"]
    pipe = make_pipeline(d, CommonStructureEFOR(max_terms=4, esr=0),
                         SpeedScheduledNarx(coef_degree=1)).fit(X, X["y"])
    model = pipe[-1]
    assert "e(t-1)" in model.noise_terms_ and model.n_iter_ > 0
    assert set(model.selected_terms_) - set(model.noise_terms_) == {
        "u(t-1)", "y(t-1)", "u(t-1)^2"}
    row = model.summary().query("term == 'y(t-1)'")
    assert np.all(np.abs(row.coef - (0.3 + 1e-3 * row.speed)) < 4.0 * row.std_err)
    y_free = model.simulate(data[0][0], 100.0)  # the free run ignores the noise terms
    assert np.all(np.isfinite(y_free))
    assert np.isfinite(pipe.score(X, X["y"]))


def test_narmax_side_by_side_with_sysidentpy_extended_least_squares():
    """Both ELS implementations remove the bias NARX least squares has on ARMAX data."""
    pytest.importorskip("sysidentpy")
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    rng = np.random.default_rng(7)
    n = 3000
    u = rng.uniform(-1, 1, n)
    e = 0.3 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.5 * y[t - 1] + u[t - 1] + e[t] + 0.8 * e[t - 1]
    ours = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, esr=0, coef_degree=0,
                              noise_lags=2).fit([(u, y)], [1.0])
    a_ours = ours.coef_per_speed_["y(t-1)"].iloc[0]
    se = ours.coef_std_err_per_speed_["y(t-1)"].iloc[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sid = FROLS(order_selection=False, n_terms=2, ylag=1, xlag=1, elag=2,
                    estimator=LeastSquares(unbiased=True), basis_function=Polynomial(degree=1),
                    model_type="NARMAX").fit(X=u[:, None], y=y[:, None])
    a_sid = float(np.ravel(sid.theta)[[r[0] for r in sid.final_model].index(1001)])
    plain = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, esr=0,
                               coef_degree=0).fit([(u, y)], [1.0])
    a_ls = plain.coef_per_speed_["y(t-1)"].iloc[0]
    assert abs(a_ls - 0.5) > 8 * se  # biased
    assert abs(a_ours - 0.5) < 3 * se and abs(a_sid - 0.5) < 3 * se
    assert abs(a_ours - a_sid) < 3 * se


def test_default_coef_degree_follows_the_number_of_speeds():
    data = arx_data(SPEEDS, 300, np.random.default_rng(0))
    one = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2).fit(data[:1], SPEEDS[:1])
    assert one.coef_degree_ == 0
    two = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2).fit(data[:2], SPEEDS[:2])
    assert two.coef_degree_ == 1
    four = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2).fit(data, SPEEDS)
    assert four.coef_degree_ == 3 and four.speed_polynomials_.shape[1] == 4
    assert SpeedScheduledNarx.from_json(four.to_json()).coef_degree_ == 3
    with pytest.raises(ValueError, match="at least 4 distinct speeds"):
        SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, coef_degree=3).fit(
            data[:2], SPEEDS[:2])


def test_set_output_default_gives_arrays_and_pandas_keeps_the_speed_index():
    data = arx_data(SPEEDS[:2], 200, np.random.default_rng(0))
    X = pd.concat([pd.DataFrame({"speed": w, "u": u, "y": y})
                   for w, (u, y) in zip(SPEEDS[:2], data, strict=True)], ignore_index=True)
    d = NarxTermDictionary(1, 1, 1)
    assert isinstance(d.fit_transform(X), pd.DataFrame)  # unconfigured: the speed index
    arr = d.set_output(transform="default").fit_transform(X)
    assert isinstance(arr, np.ndarray) and arr.shape == (400, 3)
    frame = d.set_output(transform="pandas").fit_transform(X)
    assert frame.index.name == "speed"
    sel = CommonStructureEFOR(max_terms=2, esr=0).set_output(transform="default")
    assert isinstance(sel.fit(frame, X["y"]).transform(frame), np.ndarray)


def test_top_level_imports_the_four_stages():
    import sknarx

    for name in ("RotorBearingSimulator", "NarxTermDictionary", "CommonStructureEFOR",
                 "SpeedScheduledNarx"):
        assert name in sknarx.__all__ and hasattr(sknarx, name)
