import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from narx_systems import scaled_coef_fn, simulate_system

from sknarx import (
    CommonStructureEFOR,
    IllConditionedWarning,
    NarxTermDictionary,
    SpeedScheduledNarx,
)
from sknarx.narx.terms import TermSet, parse_terms

SPEEDS = np.array([80.0, 120.0, 160.0, 200.0, 240.0, 280.0])

# Candidate true terms grouped by how strongly they may act (keeps random systems stable).
LINEAR_Y = ["y(t-1)", "y(t-2)"]
INPUT = ["u(t-1)", "u(t-2)", "u(t-1)^2", "u(t-2)^2", "u(t-1)*u(t-2)", "u(t-1)^3", "1"]
CROSS = ["y(t-1)*u(t-1)", "y(t-2)*u(t-2)", "y(t-1)*u(t-2)^2", "y(t-1)^2"]


@st.composite
def systems(draw):
    ys = draw(st.lists(st.sampled_from(LINEAR_Y), min_size=1, max_size=2, unique=True))
    us = draw(st.lists(st.sampled_from(INPUT), min_size=1, max_size=3, unique=True))
    if "u(t-1)" not in us and "u(t-2)" not in us:
        us = ["u(t-1)"] + us
    xs = draw(st.lists(st.sampled_from(CROSS), min_size=0, max_size=2, unique=True))
    terms = ys + us + xs
    base = []
    for t in terms:
        mag = {"y": 0.35, "c": 0.08}.get("y" if t in LINEAR_Y else ("c" if t in CROSS else "x"),
                                          1.0)
        sign = draw(st.sampled_from([-1.0, 1.0]))
        base.append(sign * mag * draw(st.floats(0.4, 1.0)))
    slopes = [draw(st.floats(-0.5, 0.5)) for _ in terms]
    curv = [draw(st.floats(-0.3, 0.3)) for _ in terms]
    base, slopes, curv = map(np.asarray, (base, slopes, curv))

    def coef_fn(w):
        s = (w - 180.0) / 100.0
        return base * (1.0 + 0.5 * slopes * s + 0.5 * curv * s**2)

    return terms, coef_fn, draw(st.integers(0, 2**16))


def _fit(data, speeds, **kw):
    params = dict(ny=2, nu=2, degree=3, esr=1e-9, coef_degree=2)
    params.update(kw)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IllConditionedWarning)
        return SpeedScheduledNarx(**params).fit(data, speeds)


@given(systems())
def test_exact_recovery_of_known_speed_scheduled_narx(system):
    terms, coef_fn, seed = system
    data = simulate_system(terms, coef_fn, SPEEDS, n=400, seed=seed)
    assume(all(np.max(np.abs(y)) < 50 for _, y in data))
    model = _fit(data, SPEEDS)
    assert sorted(model.selected_terms_) == sorted(terms)
    order = [model.selected_terms_.index(t) for t in terms]
    for w in (SPEEDS[1], 150.0, 275.0):
        truth = np.asarray(coef_fn(w))
        got = model.coefficients_at(w)[order]
        np.testing.assert_allclose(got, truth, rtol=1e-6, atol=1e-6 * np.max(np.abs(truth)))


@given(systems(), st.permutations(range(len(SPEEDS))))
def test_invariant_to_dataset_order(system, perm):
    terms, coef_fn, seed = system
    data = simulate_system(terms, coef_fn, SPEEDS, n=300, seed=seed)
    assume(all(np.max(np.abs(y)) < 50 for _, y in data))
    a = _fit(data, SPEEDS)
    b = _fit([data[i] for i in perm], SPEEDS[list(perm)])
    assert a.selected_terms_ == b.selected_terms_
    np.testing.assert_allclose(a.aerr_, b.aerr_, rtol=1e-8, atol=1e-12)
    scale = np.abs(a.coef_poly_).max()
    np.testing.assert_allclose(a.coef_poly_, b.coef_poly_, rtol=0, atol=1e-9 * scale)


@given(systems(), st.sampled_from([1e-5, 3e-3, 1.0, 7e2]), st.sampled_from([1e-5, 0.2, 1e4]))
def test_structure_invariant_to_signal_scale(system, y_scale, u_scale):
    terms, coef_fn, seed = system
    data = simulate_system(terms, coef_fn, SPEEDS, n=300, seed=seed)
    assume(all(np.max(np.abs(y)) < 50 for _, y in data))
    scaled = [(u * u_scale, y * y_scale) for u, y in data]
    a = _fit(data, SPEEDS)
    b = _fit(scaled, SPEEDS)
    assert a.selected_terms_ == b.selected_terms_
    # and the coefficients transform exactly as the physics says
    fn = scaled_coef_fn(a.selected_terms_, lambda w: a.coefficients_at(w), u_scale, y_scale)
    np.testing.assert_allclose(b.coefficients_at(150.0), fn(150.0), rtol=1e-6)


def test_displacement_sized_signals_with_tiny_cubes():
    terms = ["y(t-1)", "u(t-1)", "u(t-1)^3", "y(t-1)*u(t-1)^2"]
    data = simulate_system(terms, lambda w: [0.4, 1.0, 0.3, 0.05], SPEEDS, n=400, seed=4)
    # displacement around 1e-5 m: cubes are ~1e-15
    scaled = [(u, 1e-5 * y) for u, y in data]
    fn = scaled_coef_fn(terms, lambda w: [0.4, 1.0, 0.3, 0.05], 1.0, 1e-5)
    model = _fit(scaled, SPEEDS, ny=1, nu=1)
    assert sorted(model.selected_terms_) == sorted(terms)
    order = [model.selected_terms_.index(t) for t in terms]
    np.testing.assert_allclose(model.coefficients_at(200.0)[order], fn(200.0), rtol=1e-6)


@pytest.mark.parametrize("solver", ["gram", "qr"])
def test_inverse_gram_schmidt_equals_least_squares(solver):
    terms = ["y(t-1)", "y(t-2)", "u(t-1)", "u(t-2)^2", "y(t-1)*u(t-1)"]
    data = simulate_system(terms, lambda w: [0.5, -0.2, 1.0, 0.3, 0.1], SPEEDS[:4], n=500,
                           seed=2)
    rng = np.random.default_rng(0)
    noisy = [(u, y + 0.05 * rng.standard_normal(y.size)) for u, y in data]
    model = _fit(noisy, SPEEDS[:4], max_terms=6, esr=0.0, solver=solver)
    exps, ny, nu = parse_terms(model.selected_terms_)
    ts = TermSet(exps, ny, nu)
    lag = 2
    for k, (u, y) in enumerate(noisy):
        P = ts.evaluate(u, y, lag, len(y))
        theta, *_ = np.linalg.lstsq(P, y[lag:], rcond=None)
        np.testing.assert_allclose(model.coef_per_speed_.iloc[k].to_numpy(), theta,
                                   rtol=1e-8, atol=1e-10 * np.abs(theta).max())


def test_selector_reports_aerr_esr_and_per_dataset_err():
    terms = ["y(t-1)", "u(t-1)", "u(t-2)^2"]
    data = simulate_system(terms, lambda w: [0.5, 1.0, 0.2 + w / 1000], SPEEDS[:3], n=300)
    df = pd.concat([pd.DataFrame({"speed": w, "u": u, "y": y})
                    for (u, y), w in zip(data, SPEEDS[:3], strict=True)], ignore_index=True)
    P = NarxTermDictionary(2, 2, 2).fit_transform(df)
    sel = CommonStructureEFOR(esr=1e-8).fit(P, df["y"])
    assert sorted(sel.selected_terms_) == sorted(terms)
    assert sel.err_.shape == (3, 3)
    np.testing.assert_allclose(sel.aerr_, 100 * sel.err_.mean(axis=0).to_numpy())
    assert sel.esr_ == pytest.approx(100 - sel.aerr_.sum())
    assert sel.esr_ < 1e-8
    assert sel.stop_reason_ == "esr"
    assert list(sel.speeds_) == list(SPEEDS[:3])
    assert sel.get_support().sum() == 3
    assert list(sel.transform(P).columns) == sel.selected_terms_


def test_max_terms_stops_selection():
    terms = ["y(t-1)", "u(t-1)", "u(t-2)^2", "1"]
    data = simulate_system(terms, lambda w: [0.5, 1.0, 0.2, 0.1], SPEEDS[:3], n=300)
    m = _fit(data, SPEEDS[:3], max_terms=2)
    assert len(m.selected_terms_) == 2


def _oversampled_data():
    # A lightly damped oscillator sampled 3000 times per period, with a cubic stiffness,
    # driven by a smooth (low-pass) input: y(t-1) and y(t-2) are nearly collinear.
    wdt, r = 2 * np.pi / 3000, 0.99995
    a1, a2 = 2 * r * np.cos(wdt), -(r**2)
    terms = ["y(t-1)", "y(t-2)", "u(t-1)", "y(t-1)^3"]
    exps, ny, nu = parse_terms(terms)
    rng = np.random.default_rng(0)
    n, sm = 20000, 2000
    speeds = np.array([100.0, 150.0, 200.0])
    data, coefs = [], []
    for w in speeds:
        u = np.convolve(rng.standard_normal(n + 2 * sm), np.hanning(sm) / sm * 10,
                        mode="same")[sm:-sm]
        c = np.array([a1, a2, 1e-3 * (1 + w / 1000), -2e-4])
        y, at = free_run(u, c[None, :], exps, ny, nu)
        assert at < 0
        data.append((u, y))
        coefs.append(c)
    return terms, data, speeds, np.array(coefs)


@pytest.mark.parametrize("solver", ["gram", "qr"])
def test_oversampled_data_selects_true_terms(solver):
    terms, data, speeds, coefs = _oversampled_data()
    m = SpeedScheduledNarx(ny=2, nu=2, degree=3, esr=1e-10, coef_degree=1,
                           solver=solver).fit(data, speeds)
    assert sorted(m.selected_terms_) == sorted(terms)
    order = [m.selected_terms_.index(t) for t in terms]
    np.testing.assert_allclose(m.coef_per_speed_.to_numpy()[:, order], coefs, rtol=1e-6)
    assert m.condition_number_ > 100  # reported; the correlated lags make it large


def test_ill_conditioned_terms_warn_and_report_condition_number():
    rng = np.random.default_rng(0)
    x = rng.standard_normal(2000)
    P = pd.DataFrame({"a": x, "b": x + 2e-6 * rng.standard_normal(2000)})
    y = P["a"] - 0.5 * P["b"] + 0.01 * rng.standard_normal(2000)
    with pytest.warns(IllConditionedWarning, match="condition number"):
        sel = CommonStructureEFOR(esr=0.0, max_terms=2, prune=False).fit(P, y)
    assert sel.condition_number_ > 5e5
    # TSQR does not square it: the same data are fine there
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        CommonStructureEFOR(esr=0.0, max_terms=2, prune=False, solver="qr").fit(P, y)


def test_no_conditioning_warning_where_roundoff_is_harmless():
    """cond ~2e5 (the paper's settings): the Gram solver's error is ~1e-5, no warning."""
    rng = np.random.default_rng(0)
    x = rng.standard_normal(2000)
    P = pd.DataFrame({"a": x, "b": x + 1e-5 * rng.standard_normal(2000)})
    y = P["a"] - 0.5 * P["b"] + 0.01 * rng.standard_normal(2000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sel = CommonStructureEFOR(esr=0.0, max_terms=2, prune=False).fit(P, y)
    assert 1e4 < sel.condition_number_ < 6e5


from sknarx.narx.freerun import free_run  # noqa: E402
