"""Order features of stepped-speed records and the checks of a measured file."""


import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx.gap import order_features
from sknarx.gap.measured import check_measured

SPEEDS = tuple(np.linspace(81.7, 276.5, 6).round(4))


def _table(w=120.0, fs=1000.0, n=1500, extra=None, noise=0.0, seed=0):
    t = np.arange(n) / fs
    x = 1e-4 * np.cos(w * t + 0.3) + 2e-6 * np.cos(2 * w * t - 1.0)
    if extra is not None:
        x = x + extra(t)
    x = x + noise * np.random.default_rng(seed).standard_normal(n)
    return pd.DataFrame({"speed": w, "t": t, "xO1": x})


def test_order_features_recover_amplitude_and_phase():
    f = order_features(_table(), ["xO1"])
    one = f[(f.feature == "1x") & (f.window == "steady")].iloc[0]
    two = f[(f.feature == "2x") & (f.window == "steady")].iloc[0]
    np.testing.assert_allclose([np.hypot(one.re, one.im), np.arctan2(one.im, one.re)],
                               [1e-4, 0.3], rtol=1e-9)
    np.testing.assert_allclose([np.hypot(two.re, two.im), np.arctan2(two.im, two.re)],
                               [2e-6, -1.0], rtol=1e-9)


def test_line_energy_ignores_white_noise_but_sees_a_line_in_its_order_band():
    white = order_features(_table(noise=1e-6), ["xO1"])
    line = order_features(_table(noise=1e-6, extra=lambda t: 5e-6 * np.sin(2 * np.pi * 50 * t)),
                          ["xO1"])

    def bands(f):
        g = f[f.feature.str.startswith("nonsync") & (f.window == "steady")]
        return g.set_index("feature").re

    # 50 Hz at 120 rad/s is shaft order 2.62
    assert bands(white).max() < 1e-6
    b = bands(line)
    assert 3e-6 < b["nonsync 2.5-3.5x"] < 7e-6
    assert b.drop("nonsync 2.5-3.5x").max() < 1e-6


@given(n=st.integers(16, 600), n_ch=st.integers(1, 5), seed=st.integers(0, 2**16),
       omega=st.floats(20.0, 400.0))
def test_line_energy_of_all_channels_at_once_is_each_channel_alone(n, n_ch, seed, omega):
    from sknarx.orders import _line_energy

    R = np.random.default_rng(seed).standard_normal((n, n_ch))
    amps, floor = _line_energy(R, 1000.0, omega)
    for c in range(n_ch):
        a1, f1 = _line_energy(R[:, [c]], 1000.0, omega)
        assert np.array_equal(amps[c], a1[0]) and floor[c] == f1[0]


@given(duration=st.floats(0.2, 2.0), fs=st.sampled_from([500.0, 1000.0, 2048.0]),
       omega=st.floats(20.0, 400.0), start=st.sampled_from([0.0, 0.3, 1.7]),
       transient_s=st.sampled_from([0.0, 0.5]), seed=st.integers(0, 2**16))
def test_record_features_are_each_windows_least_squares_orders_and_line_energy(
        duration, fs, omega, start, transient_s, seed):
    """The features reuse each time grid's basis, window, bands and keys (cached across
    records); they must be bit for bit what a fresh least-squares fit and line energy of
    that window give, whichever grids were seen before."""
    from sknarx.orders import _EXTRA, ORDERS, _line_energy, harmonic_basis, record_features

    rng = np.random.default_rng(seed)
    t = start + np.arange(int(duration * fs)) / fs
    Y = 1e-4 * np.cos(omega * t[:, None] + rng.uniform(0, 6, 3)) + 1e-6 * rng.standard_normal(
        (t.size, 3))
    k = len(ORDERS)
    for _ in range(2):  # the second time from the cache
        keys, vals, ses, nons = record_features((omega, t, Y), ["a", "b", "c"], transient_s)
        i = 0
        for window, mask in (("transient", t < transient_s), ("steady", t >= transient_s)):
            if mask.sum() < 32:
                continue
            B = harmonic_basis(omega * t[mask], ORDERS + _EXTRA)
            coef, *_ = np.linalg.lstsq(B, Y[mask], rcond=None)
            R = Y[mask] - B @ coef
            se = np.sqrt((R**2).sum(axis=0) / max(mask.sum() - B.shape[1], 1)) * np.sqrt(
                2.0 / mask.sum())
            amps, floor = _line_energy(R, fs, omega)
            for c in range(3):
                expected = np.concatenate([coef[1:1 + 2 * k:2, c] - 1j * coef[2:2 + 2 * k:2, c],
                                           amps[c]])
                m = expected.size
                np.testing.assert_array_equal(vals[i:i + m], expected)
                np.testing.assert_array_equal(ses[i:i + m], [se[c]] * k + [floor[c]] * (m - k))
                assert all(key[:3] == (omega, window, "abc"[c]) for key in keys[i:i + m])
                assert not nons[i:i + k].any() and nons[i + k:i + m].all()
                i += m
        assert i == len(keys) == vals.size == ses.size == nons.size


def test_features_extracted_in_the_simulation_threads_equal_those_of_the_records():
    from sknarx.gap.sweep_model import SweepModel
    from sknarx.orders import feature_arrays
    from sknarx.rotor import ProbeRunout, RotorParameters

    model = SweepModel(RotorParameters(), 1000.0, 700, ("xO1", "yA"), transient_s=0.3)
    nuis, effects = np.array([1.02, 0.1, 0.99, 1.03]), (ProbeRunout(amplitude=1e-5),)
    threaded = model.feature_arrays(SPEEDS[:4], nuis, effects)
    serial = feature_arrays(model.records(SPEEDS[:4], nuis, effects), ["xO1", "yA"], 0.3)
    assert threaded[0] == serial[0]
    for a, b in zip(threaded[1:], serial[1:], strict=True):
        assert np.array_equal(a, b)


def test_several_points_simulated_together_equal_each_alone():
    """Probes and a difference Jacobian's columns share the two threads' queue: each
    point's features are bit for bit those of the point alone, and a point whose
    simulation fails gets its own exception without touching the others."""
    from sknarx.gap.sweep_model import SweepModel
    from sknarx.rotor import ProbeRunout, RotorParameters

    model = SweepModel(RotorParameters(), 1000.0, 500, ("xO1", "yA"), transient_s=0.2)
    points = [(np.array([1.02, 0.1, 0.99, 1.03]), (ProbeRunout(amplitude=1e-5),)),
              (np.array([1.0, 0.0, 1.0, 1.0]), ("not an effect",)),
              (np.array([0.9, -0.2, 1.05, 0.8]), ())]
    together = model.feature_arrays_many(SPEEDS[:3], points)
    assert isinstance(together[1], Exception)
    for i in (0, 2):
        alone = model.feature_arrays(SPEEDS[:3], *points[i])
        assert together[i][0] == alone[0]
        for a, b in zip(together[i][1:], alone[1:], strict=True):
            assert np.array_equal(a, b)
    with pytest.raises(type(together[1])):
        model.feature_arrays(SPEEDS[:3], *points[1])


def test_a_fixed_frequency_line_walks_across_order_bands():
    f = pd.concat([_table(w, noise=1e-7, extra=lambda t: 5e-6 * np.sin(2 * np.pi * 50 * t))
                   for w in (100.0, 250.0)])
    feats = order_features(f, ["xO1"])
    g = feats[feats.feature.str.startswith("nonsync") & (feats.window == "steady")]
    top = g.loc[g.groupby("speed").re.idxmax()].set_index("speed").feature
    assert top[100.0] == "nonsync 2.5-3.5x" and top[250.0] == "nonsync 0.75-1.5x"


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d.drop(columns="t"), "lack column"),
        (lambda d: d.assign(xO1=d.xO1 * 1e6), "implausible"),
        (lambda d: d.assign(xO1=np.where(d.index == 5, np.nan, d.xO1)), "NaN"),
        (lambda d: d[d.speed < 150], "at least 4"),
        (lambda d: d.rename(columns={"xO1": "probe1"}), "No measured channel.*after its DOF"),
        (lambda d: d.assign(speed=d.speed * 60 / (2 * np.pi)),
         r"speed column looks like rpm. Give it in rad/s \(rpm / 9.5493\)"),
        (lambda d: d.assign(t=np.where(d.speed == 160.0, 2 * d.t, d.t)),
         r"one sampling rate \(.*500 Hz at 160 rad/s.*\); resample them to one rate"),
        (lambda d: pd.concat([d, d[d.speed == 120.0]], ignore_index=True),
         "more than one record"),
    ],
)
def test_bad_measured_files_are_explained(mutate, match):
    d = pd.concat([_table(w) for w in (100.0, 120.0, 160.0, 200.0)], ignore_index=True)
    with pytest.raises(ValueError, match=match):
        check_measured(mutate(d))


@given(st.lists(st.floats(30.0, 1500.0), min_size=4, max_size=6, unique=True),
       st.sampled_from([500.0, 1000.0, 2000.0]), st.integers(256, 4096),
       st.floats(0.0, 0.5), st.integers(0, 2**16))
def test_a_sweep_in_rad_s_is_never_taken_for_rpm(speeds, fs, n, harmonic, seed):
    """Whatever its speeds, rate, length, 2x content and noise, a sweep whose 1x is its
    strongest line passes the speed-unit check (it may fail others, never that one)."""
    speeds = [w for w in speeds if w / (2 * np.pi) < 0.45 * fs]
    if len(speeds) < 4:
        return
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    table = pd.concat([pd.DataFrame({
        "speed": w, "t": t,
        "xO1": 1e-5 * np.cos(w * t) + harmonic * 1e-5 * np.cos(2 * w * t + 1.0)
        + 1e-7 * rng.standard_normal(n)}) for w in speeds], ignore_index=True)
    try:
        check_measured(table)
    except ValueError as exc:
        assert "rpm" not in str(exc), exc
