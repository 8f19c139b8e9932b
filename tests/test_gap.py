"""Gap diagnosis: features, gap map, file checks, and a fast blind subset end to end."""

import json
import math
import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx.gap import DiagnosisSettings, compare, diagnose, order_features
from sknarx.gap.measured import check_measured
from sknarx.testing import make_trial

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
    from sknarx.gap.features import _line_energy

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
    from sknarx.gap.features import _EXTRA, ORDERS, _line_energy, record_features
    from sknarx.orders import harmonic_basis

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
    from sknarx.gap.calibration import SweepModel
    from sknarx.gap.features import feature_arrays
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
    from sknarx.gap.calibration import SweepModel
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


def test_small_keyphasor_offsets_are_not_a_gap_but_large_ones_are():
    sim = pd.concat([_table(w, noise=1e-7, seed=1) for w in (100.0, 150.0)])
    feats = order_features(sim, ["xO1"])
    for deg, expect_gap in ((3.0, False), (25.0, True)):
        shifted = sim.copy()
        shifted["t"] = shifted["t"] - np.radians(deg) / shifted["speed"]
        cmp = compare(order_features(shifted, ["xO1"]), feats)
        assert (cmp[cmp.feature == "1x"].z2.max() > 9) == expect_gap


def _feature_frame(rng, speeds=(100.0, 150.0), channels=("xO1", "xA"), tol_1x=0.0):
    feats = ["1/3x", "1/2x", "1x", "2x", "3x", "nonsync 0-0.75x"]
    idx = pd.MultiIndex.from_product([speeds, ["steady"], channels, feats],
                                     names=["speed", "window", "channel", "feature"])
    f = idx.to_frame(index=False)
    size = np.where(f.feature == "1x", 1e-4, 5e-6)
    f["re"], f["im"] = size * rng.standard_normal((2, len(f)))
    f["se"] = 1e-7 * (1 + rng.random(len(f)))
    f["model_tol"] = np.where(f.feature == "1x", tol_1x * np.hypot(f.re, f.im), 0.0)
    return f


@given(st.integers(0, 2**31 - 1), st.floats(0.0, 0.9), st.booleans())
def test_the_calibration_residual_is_the_gap_maps_comparison(seed, tol_1x, whirl):
    # one kernel for both: what a calibration minimises is what the gap map reports,
    # channel by channel or in a probe pair's whirl
    from sknarx.gap.gapmap import fast_residual, feature_layout, whirl_layout

    rng = np.random.default_rng(seed)
    meas = _feature_frame(rng, channels=("xO1", "yO1", "xA"), tol_1x=tol_1x)
    if whirl:
        meas["whirl_tol"] = 1e-6 * rng.random(len(meas))
    sim = meas.assign(re=meas.re * (1 + 0.3 * rng.standard_normal(len(meas))),
                      im=meas.im + 2e-6 * rng.standard_normal(len(meas)),
                      se=1e-7).drop(columns=["model_tol", "whirl_tol"], errors="ignore")
    cmp = compare(meas, sim)
    index = meas.set_index(["speed", "window", "channel", "feature"]).index
    order_k, speed_idx, group_idx = feature_layout(index)
    r = fast_residual(meas.re.to_numpy() + 1j * meas.im.to_numpy(), meas.se.to_numpy(),
                      sim.re.to_numpy() + 1j * sim.im.to_numpy(), sim.se.to_numpy(),
                      order_k, speed_idx, group_idx, model_tol=meas.model_tol.to_numpy(),
                      whirl=whirl_layout(index, meas["whirl_tol"].to_numpy())
                      if whirl else None)
    n = len(meas)
    np.testing.assert_allclose(r[:n] ** 2 + r[n:] ** 2, cmp.z2.to_numpy(), rtol=1e-9)


@given(st.integers(0, 2**31 - 1), st.floats(0.0, 0.9), st.booleans(),
       st.floats(1e-6, 1e-3))
def test_a_probes_runout_widens_no_tolerance(seed, tol_1x, whirl, runout):
    # a constant per-probe vector held by both the measurement and the prediction (a
    # fitted runout) changes nothing of the comparison once it is named: the rotor's
    # part is what every share of tolerance is taken of -- in the table and in the
    # calibration's residual alike (without the keyphasor's alignment, which turns the
    # runout with the rotor and so is the one step it enters)
    from sknarx.gap.gapmap import fast_residual, feature_layout, probe_offsets, whirl_layout

    rng = np.random.default_rng(seed)
    meas = _feature_frame(rng, channels=("xO1", "yO1", "xA", "yA"), tol_1x=tol_1x)
    if whirl:
        meas["whirl_tol"] = 1e-6 * rng.random(len(meas))
    sim = meas.assign(re=meas.re * (1 + 0.3 * rng.standard_normal(len(meas))),
                      im=meas.im + 2e-6 * rng.standard_normal(len(meas)),
                      se=1e-7).drop(columns=["model_tol", "whirl_tol"], errors="ignore")
    vectors = {ch: {1.0: runout * complex(*rng.standard_normal(2)),
                    2.0: 0.3 * runout * complex(*rng.standard_normal(2))}
               for ch in ("xA", "yA")}
    index = meas.set_index(["speed", "window", "channel", "feature"]).index
    v = probe_offsets(index, vectors)
    assert np.count_nonzero(v) == np.count_nonzero(
        meas.channel.isin(["xA", "yA"]) & meas.feature.isin(["1x", "2x"]))
    shifted = {"re": lambda f: f.re + v.real, "im": lambda f: f.im + v.imag}
    plain = compare(meas, sim, max_offset_deg=0.0)
    named = compare(meas.assign(**shifted), sim.assign(**shifted), max_offset_deg=0.0,
                    probe_vectors=vectors)
    np.testing.assert_allclose(named.z2.to_numpy(), plain.z2.to_numpy(), rtol=1e-9)
    order_k, speed_idx, group_idx = feature_layout(index)
    r = fast_residual((meas.re + 1j * meas.im).to_numpy() + v, meas.se.to_numpy(),
                      (sim.re + 1j * sim.im).to_numpy() + v, sim.se.to_numpy(),
                      order_k, speed_idx, group_idx, max_offset_deg=0.0,
                      model_tol=meas.model_tol.to_numpy(), offset=v,
                      whirl=whirl_layout(index, meas["whirl_tol"].to_numpy())
                      if whirl else None)
    n = len(meas)
    np.testing.assert_allclose(r[:n] ** 2 + r[n:] ** 2, plain.z2.to_numpy(), rtol=1e-9)


def test_an_unnamed_runout_still_widens_the_comparison():
    # the other side of the test above, so that it can fail: the same runout left in the
    # prediction unnamed scales the tolerances up and hides part of the rotor's misfit
    from sknarx.gap.gapmap import probe_offsets

    rng = np.random.default_rng(5)
    meas = _feature_frame(rng, channels=("xA", "yA"))
    sim = meas.assign(re=meas.re * 1.2, se=1e-7).drop(columns="model_tol")
    vectors = {ch: {1.0: 3e-4 + 0j, 2.0: 1e-4 + 0j} for ch in ("xA", "yA")}
    v = probe_offsets(meas.set_index(["speed", "window", "channel", "feature"]).index,
                      vectors)
    shifted = {"re": lambda f: f.re + v.real, "im": lambda f: f.im + v.imag}
    m, s = meas.assign(**shifted), sim.assign(**shifted)
    named = compare(m, s, max_offset_deg=0.0, probe_vectors=vectors).excess.sum()
    assert compare(m, s, max_offset_deg=0.0).excess.sum() < 0.5 * named


def test_a_journals_harmonics_follow_its_admitted_1x_phase_error():
    # a journal's 1x 30 deg off, inside its 1x model-form tolerance: its 2x and 3x off by
    # 60 and 90 deg (locked to the orbit) are no gap; beyond the tolerance, or where
    # the 1x is trusted, they are
    rng = np.random.default_rng(3)
    sim = _feature_frame(rng, speeds=(100.0,), channels=("xA",)).drop(columns="model_tol")
    k = sim.feature.map({"1x": 1.0, "2x": 2.0, "3x": 3.0}).fillna(0.0).to_numpy()
    z = (sim.re + 1j * sim.im).to_numpy() * np.exp(1j * k * np.radians(30.0))
    meas = sim.assign(re=z.real, im=z.imag)
    harm = meas.feature.isin(["2x", "3x"]).to_numpy()
    for tol_1x, is_gap in ((0.6, False), (0.1, True), (0.0, True)):
        m = meas.assign(model_tol=np.where(meas.feature == "1x", tol_1x * 1e-4, 0.0))
        assert (compare(m, sim).z2.to_numpy()[harm].max() > 9) == is_gap, tol_1x


def _orbit_pair(radius=1e-4, se=1e-8):
    """A probe pair's 1x on a forward circular orbit (x = r, y = -j r), one speed."""
    f = pd.DataFrame({"speed": 100.0, "window": "steady", "channel": ["xO1", "yO1"],
                      "feature": "1x", "re": [radius, 0.0], "im": [0.0, -radius], "se": se})
    return f


@pytest.mark.parametrize("whirl", ["forward", "backward"])
def test_a_probe_pairs_ellipse_is_not_tolerated_as_isotropic_model_error(whirl):
    # both channels 5 % off, inside their 10 % 1x model-form tolerance: a larger circle
    # (forward whirl) is what the update's isotropic parameters leave; an ellipse
    # (backward whirl) is not, once the comparison knows the model's own ellipse
    # (``whirl_tol``) -- channel by channel the two look alike
    sim = _orbit_pair()
    eps = 0.05 * 1e-4
    d_y = -1j * eps if whirl == "forward" else 1j * eps
    meas = sim.assign(re=sim.re + [eps, d_y.real], im=sim.im + [0.0, d_y.imag],
                      model_tol=0.1 * 1e-4)
    assert compare(meas, sim).z2.max() < 2  # channel by channel
    for tol_b, is_gap in ((0.0, whirl == "backward"), (3 * eps, False)):
        z2 = compare(meas.assign(whirl_tol=tol_b), sim).z2
        assert (z2.sum() > 18) == is_gap, (whirl, tol_b)


@given(st.integers(0, 2**31 - 1))
def test_the_whirl_basis_changes_nothing_without_tolerances(seed):
    # the whirl basis is a rotation of the pair's residuals: with equal noise on both
    # channels and no model-form tolerance it leaves the pair's summed z2 unchanged
    rng = np.random.default_rng(seed)
    sim = _orbit_pair(radius=float(rng.uniform(1e-6, 1e-4)))
    meas = sim.assign(re=sim.re + 1e-6 * rng.standard_normal(2),
                      im=sim.im + 1e-6 * rng.standard_normal(2))
    plain = compare(meas, sim).z2.sum()
    np.testing.assert_allclose(compare(meas.assign(whirl_tol=0.0), sim).z2.sum(), plain,
                               rtol=1e-9)


@given(st.dictionaries(st.sampled_from(["xO1", "yO1", "xA", "yA", "xB", "yB", "xO2"]),
                       st.floats(0.01, 1.0), min_size=1))
def test_the_1x_tolerance_is_what_both_directions_of_a_probe_share(own):
    from types import SimpleNamespace

    from sknarx.gap.diagnosis import _common_1x_tolerance

    # an x/y split is no isotropic parameter's doing: neither channel of a probe pair is
    # admitted more 1x model-form error than the other's misfit, and a split's excess
    # stays for an effect (an anisotropy) to explain
    tol = _common_1x_tolerance(SimpleNamespace(mismatch={"model_tolerance": own}))
    assert tol.keys() == own.keys()
    for c, t in tol.items():
        other = {"x": "y", "y": "x"}[c[0]] + c[1:]
        assert t == (min(own[c], own[other]) if other in own else own[c])
    assert _common_1x_tolerance(None) == {}


@given(st.floats(0.01, 100.0))
def test_inflating_a_harmonic_never_widens_its_own_tolerance(scale):
    from sknarx.gap.gapmap import HARMONIC_RTOL

    # harmonics agree to a share of the *smaller* size: a candidate whose 2x grows past
    # the measured one only moves further away
    rng = np.random.default_rng(0)
    meas = _feature_frame(rng, speeds=(100.0,), channels=("xO1",))
    two = (meas.feature == "2x").to_numpy()

    def z2(s):
        sim = meas.assign(re=np.where(two, s * meas.re, meas.re),
                          im=np.where(two, s * meas.im, meas.im))
        return compare(meas, sim).z2.to_numpy()[two][0]

    if scale > 1:
        assert z2(scale * 1.1) > z2(scale) > z2(1.0)
        if scale > 2.5:  # a share of the larger size would cap z2 below 1 / rtol^2
            assert z2(scale) > 1.0 / HARMONIC_RTOL**2
    else:
        assert z2(scale * 0.9) > z2(scale) >= z2(1.0)


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


@pytest.fixture(scope="module")
def runout_trial():
    return make_trial("runout", 7, speeds=SPEEDS, n_samples=1000)


def test_blind_subset_finds_withheld_runout(runout_trial):
    measured, truth = runout_trial
    d = diagnose(measured, candidates=("runout", "crack", "anisotropy"))
    assert d["verdict"] == "runout", d["ranking"][:2]
    assert d["shrink"] > 0.5
    # each probe's own 1x runout vector; the trial's runout is one shared vector
    per_probe = d["ranking"][0]["params"]
    assert set(per_probe) == set(measured.columns) - {"speed", "t"}
    for est in per_probe.values():
        assert abs(est["1x_m"] / truth["effects"][0]["amplitude"] - 1) < 0.2
        assert est["2x_m"] < 0.2 * est["1x_m"]  # no 2x runout was put in
    assert d["where"] and d["where"][0]["order"] == "1x"


def test_blind_subset_says_no_gap_on_effect_free_data():
    measured, _ = make_trial(None, 11, speeds=SPEEDS, n_samples=1000)
    d = diagnose(measured, candidates=("runout", "crack"))
    assert d["verdict"] == "no-gap"
    # under the floor the candidates are still searched (attribute_below_floor), and
    # none passes the full test on an effect-free sweep; the document still says what
    # the gap per feature was divided by (docs/gap.md, Output)
    n = d["n_heldout_features"]
    assert d["gap_before"]["per_feature"] < d["settings"]["no_gap_per_feature"] and n > 0
    assert {r["effect"] for r in d["ranking"] if isinstance(r["effect"], str)} == {
        "runout", "crack"}
    off = diagnose(measured, candidates=("runout", "crack"),
                   settings=DiagnosisSettings(attribute_below_floor=False))
    assert off["verdict"] == "no-gap" and off["ranking"] == []
    assert d["gap_before"]["per_feature"] * n == pytest.approx(d["gap_before"]["heldout_excess"])


@pytest.mark.slow
def test_gap_command_writes_diagnosis(runout_trial, tmp_path):
    """As a user runs it, stopped with Ctrl-C once the nominal update is done and
    started again: the second run resumes, writes the outputs, and removes the steps
    it kept."""
    import signal
    import time

    measured, _ = runout_trial
    path = tmp_path / "measured.csv"
    measured.to_csv(path, index=False)
    command = [sys.executable, "-m", "sknarx", "gap", "--measured", str(path),
               "--out", str(tmp_path / "out"), "--candidates", "runout", "clearance"]
    kept = tmp_path / "out" / ".checkpoint"
    first = subprocess.Popen(command + ["--quiet"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while len(list(kept.glob("update-*.pkl"))) < 1 and first.poll() is None:
        assert time.monotonic() < deadline, "no checkpoint step written"
        time.sleep(0.2)
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=120)
    assert first.returncode == 130, err[-2000:]
    assert f"the same command again resumes from {kept}" in err
    res = subprocess.run(command, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    assert re.search(r"resuming from [1-9]\d* finished step", res.stderr), res.stderr[-2000:]
    assert not kept.exists()
    doc = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    # the keys docs/gap.md promises (an effect verdict: the conditional ones too)
    for key in ("verdict", "ranking", "where", "shrink", "gap_before", "n_heldout_features",
                "nuisance", "noise", "split", "sampling", "channels", "settings",
                "sknarx_version", "command", "provenance", "shrink_band", "gap_after",
                "regions_after"):
        assert key in doc, key
    assert doc["shrink_band"] is not None and len(doc["shrink_band"]) == 2
    assert {"commit", "date_utc", "dependencies"} <= set(doc["provenance"])
    r0 = doc["ranking"][0]
    for key in ("effect", "params", "heldout_gap_before", "heldout_gap_after", "shrink",
                "evidence"):
        assert key in r0
    assert {"speed_range", "order", "channel", "share"} <= set(doc["where"][0])
    # each order's held-out mean z2 against its own floor, as documented
    by_order = doc["gap_before"]["by_order"]
    assert set(by_order) == {"1x", "2x", "3x"}
    for k, floor in zip(("1x", "2x", "3x"), doc["settings"]["order_floors_z2"], strict=True):
        row = by_order[k]
        assert row["floor_z2"] == floor and row["n"] > 0
        assert row["over_floor"] == (row["mean_z2"] > floor)
    assert "narx" in doc and doc["narx"]["terms_measured"]
    html = (tmp_path / "out" / "report.html").read_text()
    assert "noise level: about" not in html  # the floor comes from the settings
    assert "Each order against its own floor" in html
    assert f"<td>2x</td><td>{by_order['2x']['n']}</td><td>{by_order['2x']['mean_z2']:.3g}" in html
    assert f"{doc['settings']['no_gap_per_feature']:.3g}" in html
    assert "Regenerate with" in html and doc["provenance"]["date_utc"] in html
    # the verdict with what the data cannot tell it from beside it
    assert doc["verdict"] == "runout" and "cannot tell the runout from a bent shaft" in html
    spread = doc["nominal_update"]["harmonic_spread"]
    assert spread["sigma_points"] > 0 and spread["max_m"] >= spread["median_m"] > 0
    assert f"spread over {spread['sigma_points']} sweeps" in html
    whirl = doc["nominal_update"]["backward_whirl_1x"]
    assert set(whirl["pairs"]) == {"xO1/yO1", "xA/yA"}
    assert all(v["max_m"] >= v["median_m"] > 0 for v in whirl["pairs"].values())
    assert "backward whirl" in html
    assert (tmp_path / "out" / "gap_map.png").exists()


def _entry(names, E, shrink, log_shrink):
    return {"effect": names[0] if len(names) == 1 else list(names), "heldout_gap_after": E,
            "shrink": shrink, "log_shrink": log_shrink, "score": E + 2 * len(names)}


def test_verdict_needs_breadth_as_well_as_shrink():
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.7, min_log_shrink=0.5)
    broad = _entry(["crack"], 100.0, 0.95, 0.9)
    # matches the big features only and leaves 1 per feature, twice the floor
    narrow = _entry(["clearance"], 100.0, 0.95, -0.3)
    assert decide(20.0, [broad], s, 100)["effect"] == "crack"
    assert decide(20.0, [narrow], s, 100) is None
    # under the floor the full test names the broad fit (attribute_below_floor), and
    # neither is named with that off
    assert decide(0.4, [broad], s, 100)["effect"] == "crack"
    assert decide(0.4, [narrow], s, 100) == "no-gap"
    assert decide(0.4, [broad], replace(s, attribute_below_floor=False), 100) == "no-gap"


def test_a_candidate_that_leaves_no_more_than_the_floor_needs_no_breadth():
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.7, min_log_shrink=0.5)
    # a thin model-form residual left untouched holds the log share down to 0.2, but
    # what is left (0.3 per feature) is below the floor: nothing is left to explain
    thin = _entry(["misalignment"], 30.0, 0.85, 0.2)
    assert decide(2.0, [thin], s, 100)["effect"] == "misalignment"
    # the same shares leaving 0.6 per feature, above the floor: the check stands
    assert decide(4.0, [_entry(["misalignment"], 60.0, 0.85, 0.2)], s, 100) is None
    # the waiver is not a license to remove less than min_shrink
    assert decide(2.0, [_entry(["misalignment"], 30.0, 0.65, 0.2)], s, 100) is None
    assert decide(2.0, [thin], replace(s, breadth_waived_at_floor=False), 100) is None


def test_one_order_over_its_floor_sends_a_sweep_under_the_floor_to_the_candidates():
    """A crack the nominal update followed as a softer shaft leaves only its 2x: the mean
    over every held-out feature is under the floor, the 2x's own mean is not."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide, order_floors, order_mean_z2, orders_over_floor

    # the attribution under the floor off: the orders alone send the sweep on
    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.6, min_log_shrink=0.3,
                          order_floors_z2=(2.5, 1.8, 1.8), attribute_below_floor=False)
    rows = [{"feature": f, "z2": z} for f, zs in
            (("1x", [1.0, 1.2]), ("2x", [2.0, 3.0]), ("3x", [0.5, 0.7]), ("50Hz", [9.0]))
            for z in zs]
    by_order = order_mean_z2(pd.DataFrame(rows))
    assert by_order == {"1x": {"mean_z2": 1.1, "n": 2}, "2x": {"mean_z2": 2.5, "n": 2},
                        "3x": {"mean_z2": pytest.approx(0.6), "n": 2}}  # lines are not orders
    over = orders_over_floor({k: v["mean_z2"] for k, v in by_order.items()}, s)
    assert over == {"2x": 2.5}
    crack = _entry(["crack"], 8.0, 0.8, 0.5)
    assert decide(0.4, [crack], s, 100) == "no-gap"  # the mean alone
    assert decide(0.4, [crack], s, 100, over)["effect"] == "crack"
    # sent to the candidates, a sweep none of them explains is unexplained, not no-gap
    assert decide(0.4, [_entry(["rub"], 30.0, 0.25, 0.1)], s, 100, over) is None
    # the floors unset: the mean over every feature alone decides
    assert orders_over_floor({"2x": 99.0}, replace(s, order_floors_z2=None)) == {}
    assert order_floors(replace(s, order_floors_z2=None)) == {}
    assert order_floors(s) == {"1x": 2.5, "2x": 1.8, "3x": 1.8}
    # before any candidate (the front end's early return asks decide with none)
    assert decide(0.4, [], s, 100) == "no-gap"
    assert decide(0.4, [], s, 100, over) is None
    assert decide(0.6, [], s, 100) is None


@given(e0=st.floats(0.01, 10.0), floor=st.floats(0.05, 1.0),
       z2=st.lists(st.floats(0.0, 10.0), min_size=3, max_size=3),
       floors=st.lists(st.floats(0.1, 5.0), min_size=3, max_size=3),
       shrink=st.floats(-0.5, 1.0), log_share=st.floats(-1.0, 1.0))
def test_the_order_test_only_sends_sweeps_under_the_floor_on(e0, floor, z2, floors, shrink,
                                                           log_share):
    """Above the floor the orders change nothing; under it a sweep is no-gap unless an
    order is over its own floor, and then it is decided as a sweep above the floor is;
    a higher floor never puts an order over it."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide, orders_over_floor

    n = 100
    ranking = [_entry(["crack"], (1.0 - shrink) * e0 * n, shrink, log_share)]
    s = DiagnosisSettings(no_gap_per_feature=floor, min_shrink=0.6, min_log_shrink=0.3,
                          order_floors_z2=tuple(floors))
    mean_z2 = dict(zip(("1x", "2x", "3x"), z2, strict=True))
    over = orders_over_floor(mean_z2, s)
    assert set(over) == {k for k, f in zip(("1x", "2x", "3x"), floors, strict=True)
                         if mean_z2[k] > f}
    higher = replace(s, order_floors_z2=tuple(2 * f for f in floors))
    assert set(orders_over_floor(mean_z2, higher)) <= set(over)
    plain = decide(e0, ranking, s, n)
    tested = decide(e0, ranking, s, n, over)
    if e0 > floor or not over:
        assert tested is plain or tested == plain
    else:
        assert plain == "no-gap"
        # the same sweep with the floor under it (a candidate removing min_shrink leaves
        # at most 0.4 e0, under either floor, so the breadth waiver acts alike)
        above = decide(e0, ranking, replace(s, no_gap_per_feature=e0 / 2), n)
        assert (tested is None) == (above is None)


def test_the_report_names_the_orders_that_sent_a_sweep_to_the_candidates():
    from sknarx.gap.report import _orders_text

    doc = {"gap_before": {"by_order": {
        "1x": {"mean_z2": 0.8, "n": 24, "floor_z2": 2.48, "over_floor": False},
        "2x": {"mean_z2": 2.31, "n": 24, "floor_z2": 1.81, "over_floor": True}}}}
    text = _orders_text(doc)
    assert "the 24 held-out 2x features (mean z\u00b2 2.31 against their floor 1.81" in text
    assert "1x" not in text
    assert _orders_text({"gap_before": {}}) == ""


def test_the_report_tables_each_order_against_its_floor():
    from sknarx.gap.report import _orders_table

    doc = {"gap_before": {"by_order": {
        "1x": {"mean_z2": 0.8, "n": 24, "floor_z2": 2.48, "over_floor": False},
        "2x": {"mean_z2": 2.31, "n": 24, "floor_z2": 1.81, "over_floor": True},
        "3x": {"mean_z2": 0.4, "n": 24, "floor_z2": None, "over_floor": False}}}}
    html = _orders_table(doc)
    rows = html.split("<tr>")[2:]
    assert len(rows) == 3
    assert rows[1] == "<td>2x</td><td>24</td><td>2.31</td><td>1.81</td><td>yes</td></tr>"
    assert "<td>0.8</td><td>2.48</td><td>no</td>" in rows[0]
    assert "<td>-</td>" in rows[2]  # no floor set for that order
    assert "dimensionless" in html
    assert _orders_table({"gap_before": {}}) == ""  # the order-domain front end has none


@given(e0=st.floats(0.01, 100.0), left=st.floats(0.0, 1.0), log_share=st.floats(-2.0, 1.0),
       floor=st.floats(0.05, 1.0))
def test_the_breadth_waiver_only_adds_verdicts_that_leave_the_floor(e0, left, log_share,
                                                                   floor):
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide

    n = 100
    entry = _entry(["rub"], left * e0 * n, 1.0 - left, log_share)
    s = DiagnosisSettings(no_gap_per_feature=floor, min_shrink=0.6, min_log_shrink=0.3)
    with_waiver = decide(e0, [entry], s, n)
    without = decide(e0, [entry], replace(s, breadth_waived_at_floor=False), n)
    if without is not None:
        assert with_waiver is without  # everything accepted before still is
    elif with_waiver not in (None, "no-gap"):
        # a verdict only the waiver admits removed min_shrink and left at most the floor
        assert entry["shrink"] >= 0.6 and left * e0 <= floor


@given(e0=st.floats(0.01, 100.0), left=st.floats(0.0, 1.0), log_share=st.floats(-2.0, 1.0),
       floor=st.floats(0.05, 1.0))
def test_attribution_under_the_floor_names_only_what_passes_the_full_test(e0, left,
                                                                         log_share, floor):
    """``attribute_below_floor``: above the floor nothing changes; under it the verdict
    is no-gap or a candidate that removed ``min_shrink`` and ``min_log_shrink`` -- the
    breadth waiver, which every candidate under the floor would meet, does not apply --
    and never ``unexplained``."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide

    n = 100
    entry = _entry(["anisotropy"], left * e0 * n, 1.0 - left, log_share)
    s = DiagnosisSettings(no_gap_per_feature=floor, min_shrink=0.6, min_log_shrink=0.3)
    plain = decide(e0, [entry], s, n)
    got = decide(e0, [entry], replace(s, attribute_below_floor=True), n)
    if e0 > floor:
        assert got is plain
    elif got != "no-gap":
        assert got is entry and entry["shrink"] >= 0.6 and log_share >= 0.3
    else:
        assert plain == "no-gap" and not (entry["shrink"] >= 0.6 and log_share >= 0.3)


def test_attribution_under_the_floor_is_on_by_default():
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.6, min_log_shrink=0.3)
    assert s.attribute_below_floor is True
    hidden = _entry(["anisotropy"], 8.0, 0.8, 0.5)  # 0.4 per feature before, 0.08 after
    assert decide(0.4, [hidden], s, 100)["effect"] == "anisotropy"
    assert decide(0.4, [], s, 100) == "no-gap"  # no candidate searched: nothing to name
    off = replace(s, attribute_below_floor=False)
    assert decide(0.4, [hidden], off, 100) == "no-gap"


def test_the_report_says_why_an_effect_is_named_under_the_floor():
    from sknarx.gap.report import _under_floor_text

    settings = {"no_gap_per_feature": 0.34, "min_shrink": 0.6, "min_log_shrink": 0.3}
    under = {"settings": settings, "gap_before": {"per_feature": 0.19}}
    assert _under_floor_text(under) == (
        " Under the floor, it is named because it removes at least 60 % of what is left "
        "and 30 % of its logarithm (attribute_below_floor).")
    # the package's rule holds it to what is left above the effect-free noise
    noisy = {**under, "settings": {**settings, "noise_per_feature": 0.112}}
    assert _under_floor_text(noisy) == (
        " Under the floor, it is named because it removes at least 60 % of what is left "
        "above the effect-free noise (0.112 per feature) and 30 % of its logarithm "
        "(attribute_below_floor).")
    above = {"settings": settings, "gap_before": {"per_feature": 0.5}}
    # a sweep sent on by one order over its own floor went to the candidates as usual
    order = {"settings": settings, "gap_before": {"per_feature": 0.19, "by_order": {
        "2x": {"over_floor": True, "n": 20, "mean_z2": 2.3, "floor_z2": 1.81}}}}
    assert _under_floor_text(above) == _under_floor_text(order) == ""


@given(lead_left=st.floats(0.05, 0.9), pair_share=st.floats(0.01, 1.0),
       form_share=st.floats(0.5, 1.5), gain=st.one_of(st.none(), st.floats(0.0, 0.9)))
def test_a_member_that_barely_beats_its_linear_form_is_left_out(lead_left, pair_share,
                                                                form_share, gain):
    """``linear_form_gain``: a candidate whose tested member removes less than ``gain``
    of what its linear form leaves is not chosen -- the verdict falls to the others as if
    it had not been fitted -- and every other candidate is decided as without the test
    (off: ``gain`` None, nothing changes)."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import beats_linear_form, decide

    n, e0 = 100, 5.0
    E0 = e0 * n
    lead = _entry(["clearance"], lead_left * E0, 1.0 - lead_left, 0.6)
    E_pair = pair_share * lead["heldout_gap_after"]
    pair = _entry(["clearance", "anisotropy"], E_pair, 1.0 - E_pair / E0, 0.7)
    # the clearance with an isotropic support in the anisotropy's place
    pair["linear_form_tests"] = [{"member": "anisotropy", "linear_form":
                                  "support-flexibility", "heldout_gap_after":
                                  min(form_share * E_pair, lead["heldout_gap_after"]),
                                  "outcome": "effect"}]
    s = DiagnosisSettings(no_gap_per_feature=0.34, min_shrink=0.6, min_log_shrink=0.3,
                          pair_trigger=0.5, pair_gain=0.3, pair_rival_shrink=None,
                          linear_form_gain=None)
    plain = decide(e0, [lead, pair], s, n)
    got = decide(e0, [lead, pair], replace(s, linear_form_gain=gain), n)
    form_left = pair["linear_form_tests"][0]["heldout_gap_after"]
    # the share of what the form leaves that the pair removes, against the gain
    kept = gain is None or 1.0 - E_pair / form_left >= gain
    assert beats_linear_form(pair, gain) is kept
    assert beats_linear_form(lead, gain)  # no member tested: nothing to judge
    if kept:
        assert got is plain
    else:
        assert got is not pair and got == decide(e0, [lead], s, n)


def test_the_report_says_when_a_member_did_too_little_beyond_its_linear_form():
    from sknarx.gap.report import _linear_form_text

    entry = {"heldout_gap_after": 90.0, "linear_form_tests": [
        {"member": "anisotropy", "linear_form": "support-flexibility",
         "heldout_gap_after": 100.0, "outcome": "effect"}]}
    assert _linear_form_text(entry) == (
        "anisotropy tested against its linear form support-flexibility: an effect (the "
        "linear form leaves 100, 10 % of which it removes)")
    assert _linear_form_text(entry, 0.3) == (
        "anisotropy tested against its linear form support-flexibility: model error (the "
        "linear form leaves 100, 10 % of which it removes, under the 30 % an effect must "
        "remove: left out of the verdict)")
    assert _linear_form_text(entry, 0.05) == _linear_form_text(entry)


def test_a_pair_replaces_the_single_only_when_the_single_leaves_a_gap_it_removes():
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.7, min_log_shrink=0.5,
                          pair_trigger=1.0, pair_gain=0.5)
    single = _entry(["runout"], 300.0, 0.98, 0.6)  # leaves 3 per feature
    pair = _entry(["runout", "crack"], 20.0, 0.999, 0.95)
    assert decide(50.0, [single, pair], s, 100)["effect"] == ["runout", "crack"]
    weak = _entry(["runout", "crack"], 200.0, 0.985, 0.7)  # removes only a third of it
    assert decide(50.0, [single, weak], s, 100)["effect"] == "runout"
    small = _entry(["runout"], 50.0, 0.999, 0.9)  # leaves 0.5 per feature: no pair
    assert decide(50.0, [small, pair], s, 100)["effect"] == "runout"
    # with a stated margin (the order-domain rule) the pair must also score that much
    # lower: 20 + 4 against 300 + 2 passes 10, not 300
    assert decide(50.0, [single, pair], replace(s, pair_margin=10.0),
                  100)["effect"] == ["runout", "crack"]
    strict = replace(s, pair_margin=300.0)
    assert decide(50.0, [single, pair], strict, 100)["effect"] == "runout"


def test_a_pair_of_rival_readings_gives_way_to_the_better_of_them():
    """Two candidates that each remove most of the held-out gap alone are rival readings
    of one signature (a rub and a crack on an independent plant's rub): the pair is not
    named, the better single is. A pair whose weaker member alone removes less than
    ``pair_rival_shrink`` -- a true pair's partner seldom explains much on its own -- or
    one of whose members was never fitted alone, is decided as before."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import decide, rivals

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.7, min_log_shrink=0.5,
                          pair_trigger=1.0, pair_gain=0.5, pair_rival_shrink=0.8)
    rub = _entry(["rub"], 300.0, 0.99, 0.6)  # leaves 3 per feature
    crack = _entry(["crack"], 900.0, 0.97, 0.3)  # alone removes 0.97
    pair = _entry(["rub", "crack"], 20.0, 0.999, 0.95)
    assert rivals(pair, [rub, crack], 0.8)
    assert decide(50.0, [rub, crack, pair], s, 100)["effect"] == "rub"
    assert decide(50.0, [rub, crack, pair], replace(s, pair_rival_shrink=None),
                  100)["effect"] == ["rub", "crack"]
    partner = _entry(["crack"], 20000.0, 0.5, 0.1)  # alone removes half: no rival
    assert decide(50.0, [rub, partner, pair], s, 100)["effect"] == ["rub", "crack"]
    assert decide(50.0, [rub, pair], s, 100)["effect"] == ["rub", "crack"]  # not fitted
    # fitted alone twice (on the rotor as given and in a reading, best first): the
    # better fit is what the member removes alone, whichever entry comes last
    crack_in_reading = _entry(["crack"], 30000.0, 0.4, 0.1)
    assert rivals(pair, [rub, crack, crack_in_reading], 0.8)
    assert decide(50.0, [rub, crack, pair, crack_in_reading], s, 100)["effect"] == "rub"


def test_a_pair_set_aside_as_rivals_is_stated_beside_the_verdict():
    """Where the rival test named the single, the document says which pair it set aside
    and what each member removes alone (``rival_pair``), and the report says why; where
    it changed nothing (no rivals, or the test off), neither says anything."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import conclude, rival_pair_set_aside
    from sknarx.gap.report import _rival_text

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.7, min_log_shrink=0.5,
                          pair_trigger=1.0, pair_gain=0.5, pair_rival_shrink=0.8,
                          n_bootstrap=20)
    rub = _entry(["rub"], 300.0, 0.99, 0.6)
    crack = _entry(["crack"], 900.0, 0.97, 0.3)
    pair = _entry(["rub", "crack"], 20.0, 0.999, 0.95)
    ranking = [pair, rub, crack]
    aside = rival_pair_set_aside(ranking, s, 100)
    assert aside["effect"] == ["rub", "crack"]
    assert aside["members_alone"] == {"rub": 0.99, "crack": 0.97}
    assert rival_pair_set_aside(ranking, replace(s, pair_rival_shrink=None), 100) is None
    assert rival_pair_set_aside([pair, rub, _entry(["crack"], 9e4, 0.3, 0.1)], s, 100) is None
    cmp0 = pd.DataFrame({"speed": np.repeat(np.arange(10.0), 10), "excess": 5.0,
                         "gap": 1e-6, "window": "steady", "channel": "xA", "feature": "1x"})
    chosen = {**rub, "_cmp": cmp0.assign(excess=0.05)}
    doc = conclude(chosen, [pair, chosen, crack], cmp0, [], s)
    assert doc["verdict"] == "rub" and doc["rival_pair"]["effect"] == ["rub", "crack"]
    text = _rival_text(doc)
    assert "rub + crack removed more (100 %)" in text
    assert "at least 80 %" in text and "rub 99 %, crack 97 %" in text
    assert "rival_pair" not in conclude(chosen, [chosen, crack], cmp0, [], s)
    assert _rival_text({"verdict": "rub"}) == ""


def test_an_unexplained_verdict_says_which_candidate_came_closest_and_what_it_missed():
    """``unexplained`` carries ``closest``: the candidate the verdict rule judged (the
    pair where it earns its place), the tests it failed and their thresholds, and the
    report says it in a sentence: a shrink short of ``min_shrink``, a breadth short of
    ``min_log_shrink`` (waived at the floor, so not listed there), or both. ``decide``
    and ``closest`` apply the same tests (``shortfalls``), so an entry with nothing
    short is named."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import closest, conclude, decide, shortfalls
    from sknarx.gap.report import closest_text

    s = DiagnosisSettings(no_gap_per_feature=0.5, min_shrink=0.6, min_log_shrink=0.3,
                          pair_trigger=1.0, pair_gain=0.3, pair_rival_shrink=None,
                          linear_form_gain=None)
    cmp0 = pd.DataFrame({"speed": np.repeat(np.arange(10.0), 10), "excess": 5.0,
                         "gap": 1e-6, "window": "steady", "channel": "xA", "feature": "1x"})
    narrow = _entry(["rub"], 400.0, 0.87, 0.2)  # leaves 4 per feature
    weak = _entry(["crack"], 1500.0, 0.5, 0.1)
    assert decide(50.0, [narrow, weak], s, 100) is None
    doc = conclude(None, [narrow, weak], cmp0, [], s, 100)
    near = doc["closest"]
    assert doc["verdict"] == "unexplained" and near["effect"] == "rub"
    assert near["short_of"] == ["breadth"] and near["shrink"] == 0.87
    assert (near["min_shrink"], near["min_log_shrink"]) == (0.6, 0.3)
    text = closest_text(doc)
    assert text == (" The closest candidate, rub, removes 87 % of the held-out gap but "
                    "only 20 % of its logarithm, where a named effect needs 30 %: it "
                    "matches the largest features, not the many others.")
    assert shortfalls(_entry(["rub"], 400.0, 0.5, 0.4), s, 100) == ["shrink"]
    assert shortfalls(weak, s, 100) == ["shrink", "breadth"]
    assert "needs 60 % and 30 %" in closest_text(
        {"closest": closest([weak], s, 100)})
    # leaving no more than the floor waives the breadth test: only the shrink is short
    flat = _entry(["rub"], 40.0, 0.55, 0.1)
    assert shortfalls(flat, s, 100) == ["shrink"]
    assert shortfalls(flat, s, 100, under=True) == ["shrink", "breadth"]
    # the pair the rule prefers is the one judged
    pair = _entry(["rub", "crack"], 250.0, 0.9, 0.25)
    assert closest([narrow, weak, pair], s, 100)["effect"] == ["rub", "crack"]
    named = _entry(["rub"], 100.0, 0.9, 0.5)
    assert shortfalls(named, s, 100) == [] and decide(50.0, [named], s, 100) is named
    assert closest_text({"verdict": "rub"}) == ""
    assert "closest" not in conclude(None, [], cmp0, [], s, 100)


@given(st.lists(st.tuples(st.sampled_from(["rub", "crack", "runout", "clearance"]),
                          st.floats(1.0, 5000.0), st.floats(-1.0, 1.0)),
                min_size=1, max_size=4, unique_by=lambda t: t[0]),
       st.floats(1.0, 5000.0), st.floats(0.0, 1.0))
def test_the_rival_test_only_ever_turns_a_pair_into_the_best_single(singles, pair_E, share):
    """Whatever the fits, the rival-pair test changes a verdict only from a pair to the
    best single (it never names another pair, and never touches a single verdict)."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import preferred

    entries = [_entry([n], E, sh, 0.5) for n, E, sh in singles]
    names = [n for n, _, _ in singles][:2]
    if len(names) == 2:
        entries.append(_entry(names, pair_E, 0.9, 0.5))
    s = DiagnosisSettings(pair_trigger=0.5, pair_gain=0.3, pair_rival_shrink=share)
    with_test = preferred(entries, s, 100)
    without = preferred(entries, replace(s, pair_rival_shrink=None), 100)
    best = min((e for e in entries if isinstance(e["effect"], str)), key=lambda e: e["score"])
    assert with_test is without or (isinstance(without["effect"], list)
                                     and with_test is best)


def _given_fit(names, E, n_params, model_error=None):
    """A candidate fit with a held-out table of 100 features sharing ``E`` equally."""
    from sknarx.gap.core import CandidateFit

    cmp = pd.DataFrame({"speed": np.repeat(np.arange(10.0), 10), "window": "steady",
                        "channel": "xA", "feature": np.tile([f"f{i}" for i in range(10)], 10),
                        "excess": E / 100.0, "gap": 1e-6})
    return CandidateFit(names=tuple(names), params=[{}] * len(names) if len(names) != 1
                        else {}, params_std={}, n_params=n_params, heldout_excess=E, cmp=cmp,
                        details={"model_error": model_error} if model_error else {})


class _GivenFits:
    """A front end whose fits are given, so the search's rules can be read alone."""

    def __init__(self, fits, forms):
        self.fits, self.forms, self.asked = fits, forms, []

    def fit(self, names):
        return self.fits[names]

    def continue_fit(self, fit):
        return None

    def partners(self, lead, others, k):
        return list(others)[:k]

    def fit_pair(self, lead, partner):
        return self.fits[(lead.names[0], partner)]

    def refit_members(self, pair):
        return []

    def linear_forms(self, fit):
        self.asked.append(fit.names)
        return self.forms.get(fit.names, [])


def _search_given(fits, forms, e0=20.0, linear_form_gain=None, **settings):
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import conclude, decide, search

    s = DiagnosisSettings(no_gap_per_feature=0.3, min_shrink=0.6, min_log_shrink=0.3,
                          pair_trigger=0.5, pair_gain=0.3, n_bootstrap=10,
                          linear_form_gain=linear_form_gain, **settings)
    front = _GivenFits(fits, forms)
    E0 = 100 * e0
    cmp0 = _given_fit((), E0, 0).cmp
    ranked = search(front, [n[0] for n in fits if len(n) == 1], E0, cmp0, 100, s)
    choice = decide(e0, ranked, s, 100)
    return front, ranked, conclude(choice, ranked, cmp0, [], s)


def test_a_partner_that_only_changes_the_linear_rotor_is_model_error_not_an_effect():
    # the ROSS plant's rubs came out as rub + anisotropy, the anisotropy's two pedestal
    # stiffnesses within 4-30 % of each other: a soft support, which is model error
    support = {"support-flexibility": {"k": 1.07e7, "mass": 31.8, "damping": 6046.0}}
    fits = {("rub",): _given_fit(["rub"], 400.0, 5),
            ("anisotropy",): _given_fit(["anisotropy"], 1500.0, 4),
            ("rub", "anisotropy"): _given_fit(["rub", "anisotropy"], 100.0, 9)}
    # the isotropic form does as well (one parameter fewer buys two of excess)
    forms = {("rub", "anisotropy"): [_given_fit(["rub"], 101.5, 8, support)]}
    front, ranked, doc = _search_given(fits, forms)
    assert ("rub", "anisotropy") in front.asked
    assert doc["verdict"] == "rub" and doc["model_error"] == support
    assert [r["heldout_gap_after"] for r in ranked if r["effect"] == "rub"] == [101.5]
    assert not any(r["effect"] == ["rub", "anisotropy"] for r in ranked)
    # an anisotropic support does what the isotropic one cannot: the pair stands
    forms = {("rub", "anisotropy"): [_given_fit(["rub"], 140.0, 8, support)]}
    _, ranked, doc = _search_given(fits, forms)
    assert doc["verdict"] == ["rub", "anisotropy"] and "model_error" not in doc


def test_pairs_are_searched_below_the_trigger_that_names_them_and_said_so():
    """A weak second effect beside a dominant one (a mild anisotropy under a runout
    leaving 0.3 per feature): pairs are searched from ``pair_search_trigger`` (0.1) and
    ranked, but named only where the single leaves more than ``pair_trigger`` (0.5);
    the verdict names the single and says which pair it did not name and why. The blind
    benchmark scored rankings searched this way."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import effect_names, pair_search_from
    from sknarx.gap.report import under_trigger_text
    from sknarx.gap.settings import ORDER_DOMAIN_SETTINGS

    fits = {("runout",): _given_fit(["runout"], 30.0, 12),
            ("anisotropy",): _given_fit(["anisotropy"], 1500.0, 4),
            ("runout", "anisotropy"): _given_fit(["runout", "anisotropy"], 9.0, 16)}
    _, ranked, doc = _search_given(fits, {})
    assert ranked[0]["effect"] == ["runout", "anisotropy"]
    assert doc["verdict"] == "runout"
    under = doc["pair_under_trigger"]
    assert under["effect"] == ["runout", "anisotropy"] and under["single"] == "runout"
    assert under["single_leaves_per_feature"] == pytest.approx(0.3)
    assert under["removes_of_single"] == pytest.approx(0.7)
    assert under["pair_trigger"] == 0.5
    assert under_trigger_text(doc) == (
        " The pair runout + anisotropy is ranked and removes 70 % of what runout alone "
        "leaves, but runout already leaves 0.3 per feature, no more than the 0.5 a second "
        "effect must explain to be named: a lead to check, not a finding.")
    # searched only from pair_trigger (the earlier default): no pair, nothing to say
    _, ranked, doc = _search_given(fits, {}, pair_search_trigger=0.5)
    assert all(len(effect_names(r)) == 1 for r in ranked)
    assert doc["verdict"] == "runout" and "pair_under_trigger" not in doc
    assert under_trigger_text(doc) == ""
    # a lead leaving less than the search trigger gets no partner
    fits[("runout",)] = _given_fit(["runout"], 8.0, 12)
    _, ranked, doc = _search_given(fits, {})
    assert all(len(effect_names(r)) == 1 for r in ranked)
    # above pair_trigger the pair is named, and nothing is set aside
    fits[("runout",)] = _given_fit(["runout"], 80.0, 12)
    _, _, doc = _search_given(fits, {})
    assert doc["verdict"] == ["runout", "anisotropy"] and "pair_under_trigger" not in doc
    # a pair that is not searched cannot be named: the search starts at the lower one
    assert pair_search_from(DiagnosisSettings()) == 0.1
    assert pair_search_from(DiagnosisSettings(pair_trigger=0.05)) == 0.05
    assert pair_search_from(ORDER_DOMAIN_SETTINGS) == 0.0


def test_an_effect_left_with_model_error_alone_is_a_no_gap_verdict_with_it_stated():
    support = {"support-flexibility": {"k": 3e7, "mass": 12.0, "damping": 900.0}}
    # 0.08 per feature: under the pair search's trigger (0.1), so no pairs
    fits = {("anisotropy",): _given_fit(["anisotropy"], 8.0, 4),
            ("crack",): _given_fit(["crack"], 1200.0, 3)}
    forms = {("anisotropy",): [_given_fit([], 8.5, 3, support)]}
    _, ranked, doc = _search_given(fits, forms)
    assert doc["verdict"] == "no-gap" and doc["model_error"] == support
    assert doc["shrink"] == 0.0 and ranked[0]["effect"] == []
    # where the isotropic support leaves more, the anisotropy is the effect
    forms = {("anisotropy",): [_given_fit([], 90.0, 3, support)]}
    _, _, doc = _search_given(fits, forms)
    assert doc["verdict"] == "anisotropy"


def test_the_best_single_and_the_best_pair_are_both_tested_whatever_the_thresholds():
    """The benchmark searches with one pair trigger and re-scores with another: the
    effect-or-model-error test must not depend on which of the two contenders the
    search's thresholds preferred. Each entry says what the test found."""
    from sknarx.gap.core import decide
    from sknarx.gap.report import _linear_form_text

    support = {"support-flexibility": {"k": 2e7, "mass": 15.0, "damping": 800.0}}
    fits = {("anisotropy",): _given_fit(["anisotropy"], 150.0, 4),  # 1.5 per feature
            ("crack",): _given_fit(["crack"], 1200.0, 3),
            ("anisotropy", "crack"): _given_fit(["anisotropy", "crack"], 60.0, 7)}
    # the lone anisotropy is only a soft support; in the pair it is more than that
    forms = {("anisotropy",): [_given_fit([], 151.0, 3, support)],
             ("anisotropy", "crack"): [_given_fit(["crack"], 300.0, 6, support)]}
    front, ranked, doc = _search_given(fits, forms)
    assert set(front.asked) == {("anisotropy",), ("anisotropy", "crack")}
    assert doc["verdict"] == ["anisotropy", "crack"]  # preferred under these thresholds
    pair = next(r for r in ranked if r["effect"] == ["anisotropy", "crack"])
    assert pair["linear_form_tests"][0]["outcome"] == "effect"
    assert _linear_form_text(pair).endswith(
        "an effect (the linear form leaves 300, 80 % of which it removes)")
    alone = next(r for r in ranked if r["effect"] == [])
    assert alone["replaces"]["effect"] == ["anisotropy"]
    assert not any(r["effect"] == "anisotropy" for r in ranked)
    assert "replaces anisotropy" in _linear_form_text(alone)
    # thresholds that keep the single (no pair gain asked of 60 against 151 is met):
    # the single is the support, tested already -- no-gap with the model error
    from sknarx.gap import DiagnosisSettings
    strict = DiagnosisSettings(no_gap_per_feature=0.3, min_shrink=0.6, min_log_shrink=0.3,
                               pair_trigger=0.5, pair_gain=0.9)
    assert decide(20.0, ranked, strict, 100)["effect"] == []


def test_with_a_linear_form_gain_the_next_contender_is_tested_too():
    """``linear_form_gain`` leaves out a pair whose member beat its form by too little;
    the pair the verdict would then name must face the same test, not be named
    untested (with the gain unset, the search is as before)."""
    support = {"support-flexibility": {"k": 2e7, "mass": 15.0, "damping": 800.0}}
    fits = {("rub",): _given_fit(["rub"], 400.0, 5),
            ("anisotropy",): _given_fit(["anisotropy"], 1500.0, 4),
            ("clearance",): _given_fit(["clearance"], 1800.0, 2),
            ("rub", "anisotropy"): _given_fit(["rub", "anisotropy"], 100.0, 9),
            ("rub", "clearance"): _given_fit(["rub", "clearance"], 150.0, 7)}
    # the anisotropy beats its form (score 126 against 118) but removes 9 % of what it
    # leaves; the clearance in the next pair is no more than a linear change either
    forms = {("rub", "anisotropy"): [_given_fit(["rub"], 110.0, 8, support)],
             ("rub", "clearance"): [_given_fit(["rub"], 151.0, 6, support)]}
    front, _, doc = _search_given(fits, forms)
    assert ("rub", "clearance") not in front.asked
    assert doc["verdict"] == ["rub", "anisotropy"]
    front, ranked, doc = _search_given(fits, forms, linear_form_gain=0.3)
    assert ("rub", "clearance") in front.asked
    assert doc["verdict"] == "rub" and doc["model_error"] == support
    assert not any(r["effect"] == ["rub", "clearance"] for r in ranked)


@pytest.mark.slow
def test_a_soft_isotropic_support_is_model_error_not_an_anisotropy():
    """End to end on the sweep front end: housings on a soft pedestal, the same in x and
    y, fit as an anisotropy with nearly equal stiffnesses; the isotropic form does as
    well, so the verdict is no-gap with the support stated as model error."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.rotor import MeasurementNoise, RotorBearingSimulator, SupportFlexibility

    support = SupportFlexibility(k=4e6, mass=30.0, damping=1000.0)
    sim = RotorBearingSimulator(effects=[support, MeasurementNoise(snr_db=35.0)], seed=3)
    measured = sim.sweep(list(SPEEDS), fs=1000.0, n_samples=1000, settle=0.0,
                         progress=False)[["speed", "t", "xO1", "yO1", "xA", "yA"]]
    fast = DiagnosisSettings(update_nominal=False, n_probe=8, max_nfev=8)
    d = diagnose(measured, candidates=("anisotropy",), settings=fast, exhaustive=True)
    assert d["gap_before"]["per_feature"] > 10 * fast.no_gap_per_feature  # a real gap
    assert d["verdict"] == "no-gap" and d["ranking"][0]["effect"] == []
    fitted = d["model_error"]["support-flexibility"]
    assert fitted == d["ranking"][0]["model_error"]["support-flexibility"]
    assert 0.5 < fitted["k"] / support.k < 2.0


def test_support_flexibility_is_the_anisotropy_with_equal_stiffnesses():
    from sknarx.rotor import RotorBearingSimulator, SupportAnisotropy, SupportFlexibility

    aniso = SupportAnisotropy(kx=8e6, ky=8e6, mass=20.0, damping=500.0, probes="frame")
    form = aniso.linear_form_of()
    assert isinstance(form, SupportFlexibility)
    assert SupportAnisotropy.linear_form is SupportFlexibility
    assert (form.k, form.mass, form.damping, form.probes) == (8e6, 20.0, 500.0, "frame")
    a = RotorBearingSimulator(effects=[aniso]).simulate_columns(150.0, n_samples=200, settle=0.1)
    b = RotorBearingSimulator(effects=[form]).simulate_columns(150.0, n_samples=200, settle=0.1)
    for col in ("xA", "yA", "xO1", "yB"):
        np.testing.assert_array_equal(a[col], b[col])
    with pytest.raises(ValueError, match="probes"):
        SupportFlexibility(probes="shaft")


def _calibration_setup(measured):
    """What a calibration needs from measured records started from rest: the nominal
    sweep model, the order features and the training speeds (every other step)."""
    from sknarx.gap.calibration import SweepModel
    from sknarx.rotor import RotorParameters

    measured, info = check_measured(measured, None)
    model = SweepModel(base=RotorParameters(), fs=info["fs"], n_samples=info["n_samples"],
                       channels=tuple(info["channels"]))
    train = np.array(info["speeds"])[0::2]
    meas = order_features(measured, info["channels"], 0.5)
    return model, meas, train, info["channels"]


@pytest.mark.slow
def test_calibration_escapes_the_wrong_basin_of_a_crack_angle():
    # seed 5068 of the blind benchmark: the cheapest Sobol probe sits near angle pi
    # and converges there (cost ~6,200); the true basin is near 0 (cost ~290)
    from sknarx.gap.calibration import calibrate
    from sknarx.rotor import EFFECTS

    measured, truth = make_trial("crack", 5068)
    model, meas, train, _ = _calibration_setup(measured)
    cal0 = calibrate(model, meas, train, (), max_nfev=15)
    # the station is held (its search is tested below): this is about the angle's basin
    cal = calibrate(model, meas, train, [EFFECTS["crack"]], starts=[cal0.x], max_nfev=15,
                    fixed=[{"station": "A-O1"}])
    true = truth["effects"][0]
    err = np.angle(np.exp(1j * (cal.effect_params[0]["angle"] - true["angle"])))
    assert abs(err) < 0.2
    assert abs(cal.effect_params[0]["depth"] / true["depth"] - 1) < 0.2


@pytest.mark.slow
def test_candidates_start_from_nominal_stiffness_not_from_what_the_nuisance_fit_absorbed():
    # the nuisance-only fit absorbs part of a crack in the stiffness scale. Seed 21 (0.92
    # for the rig's 1.01): a crack started there converged to a held-out gap of ~6,600
    # against the truth's ~70 (shrink 0.58 -> unexplained). Since the top speed step is
    # always calibrated (core.alternating_split) seed 21 absorbs only 3 %; seed 22
    # absorbs 18 % (1.149, on the bound, for the rig's 0.975; measured: fitted 0.953,
    # shrink 0.999 against the oracle's 0.998). Since the update fits where c_O1, c_O2
    # act (tilt_share_O) seed 22 absorbs 2.6 % and seed 24 6.6 % (1.071 for 1.005);
    # seed 23 (8.8 %) names the crack but trades depth for the element's stiffness
    # (closed 0.84 for the rig's 0.98)
    from sknarx.rotor import BreathingCrack
    from sknarx.testing import oracle_gap

    measured, truth = make_trial("crack", 24)
    d = diagnose(measured, candidates=("crack",))
    absorbed = d["nuisance"]["calibrated"]["stiffness_scale"]
    assert abs(absorbed / truth["nuisance"]["stiffness_scale"] - 1) > 0.05  # the trap is there
    assert d["verdict"] == "crack"
    E0 = d["gap_before"]["heldout_excess"]
    oracle = 1 - oracle_gap(measured, truth, d["split"]["heldout_speeds"]) / E0
    assert d["shrink"] >= 0.95 * oracle
    # the cracked segment's closed stiffness (the candidate's scales on top of the
    # updated nominal k1) is the rig's, not the trap's
    upd = {p["parameter"]: p["change"] for p in d["nominal_update"]["parameters"]}
    best = d["ranking"][0]
    closed = BreathingCrack.from_params(best["params"]).element_scale
    fitted = best["nuisance"]["stiffness_scale"] * (1 + upd["k1"]) * closed
    rig, trap = truth["nuisance"]["stiffness_scale"], absorbed
    assert abs(fitted - rig) < 0.5 * abs(trap - rig)
    # seed 21: within 3 % while harmonics had to agree to the noise; with the 30 %
    # harmonic tolerance (gapmap.HARMONIC_RTOL) the 2x sets the depth less tightly and
    # depth and element stiffness trade: +4.4 % (depth 0.47 for 0.42); seed 22: -2.3 %
    assert abs(fitted / rig - 1) < 0.06


def _settled_sweep(seed=3, n_speeds=8):
    """A mismatched rotor measured after settling at each speed (no transient)."""
    from sknarx.rotor import MeasurementNoise, RotorBearingSimulator, RotorParameters

    b = RotorParameters()
    p = b.replace(k1=b.k1 * 1.02, c_a=b.c_a * 0.97, unbalance_phase=0.7)
    sim = RotorBearingSimulator(p, effects=[MeasurementNoise(snr_db=30)], seed=seed)
    speeds = list(np.linspace(81.7, 276.5, n_speeds).round(3))
    tab = sim.sweep(speeds, fs=1000.0, n_samples=600, settle=2.0, progress=False)
    return tab[["speed", "t", "xO1", "yO1", "xA", "yA"]]


def test_transient_or_settled_is_read_from_the_records(runout_trial):
    from sknarx.gap.features import TRANSIENT_RATIO, free_response_decay

    channels = ["xO1", "yO1", "xA", "yA"]
    from_rest = free_response_decay(runout_trial[0], channels)
    settled = free_response_decay(_settled_sweep(), channels)
    assert from_rest.transient.all() and (from_rest.ratio > 1.5 * TRANSIENT_RATIO).all()
    assert (from_rest.decayed_s > 0).all() and (from_rest.decayed_s < 1.0).all()
    assert (settled.ratio < TRANSIENT_RATIO).mean() > 0.8
    assert (settled.decayed_s[~settled.transient] == 0).all()


def test_a_settled_sweep_is_compared_with_settled_simulations_and_is_no_gap():
    """Records taken after settling have no transient window: treating their first
    0.5 s as a transient against a simulation started from rest made a gap of nothing.

    Two candidates are searched under the floor (``attribute_below_floor``) on these
    settled records and neither may be named; the whole library took 80 s of the suite
    here for the same verdict (the blind benchmark's settled sweeps score its false
    alarms against the whole library)."""
    res = diagnose(_settled_sweep(), candidates=("runout", "crack"))
    assert {r["effect"] for r in res["ranking"]} == {"runout", "crack"}
    rec = res["records"]
    assert rec["starts_with_transient"] is False and rec["transient_window_s"] == 0.0
    assert rec["simulation_settle_s"] > 0
    # measured 0.09 per feature against the 0.34 floor
    assert res["gap_before"]["per_feature"] < 0.5 * DiagnosisSettings().no_gap_per_feature
    assert res["verdict"] == "no-gap"


@pytest.mark.slow
def test_an_effect_free_sweep_of_a_mismatched_rotor_is_no_gap_with_the_updates_listed():
    """Segment stiffness, a damper, a bearing damper and the clearance off by 15-40 %:
    four global scalars cannot absorb that (the gap stays several times the floor, and
    the full library then called it `unexplained`); the nominal update does, and says
    what."""
    from dataclasses import replace

    from sknarx.gap import DiagnosisSettings
    from sknarx.rotor import MeasurementNoise, RotorBearingSimulator, RotorParameters

    b = RotorParameters()
    rig = b.replace(k1=b.k1 * 0.85, c_d2=b.c_d2 * 0.7, clearance=0.7e-6, unbalance_phase=0.7,
                    c_a=b.c_a * 1.2)
    sim = RotorBearingSimulator(rig, effects=[MeasurementNoise(snr_db=30)], seed=3)
    speeds = list(np.linspace(81.7, 276.5, 10).round(3))
    tab = sim.sweep(speeds, fs=1000.0, n_samples=1000, settle=2.0, progress=False)
    measured = tab[["speed", "t", "xO1", "yO1", "xA", "yA"]]

    res = diagnose(measured, candidates=())
    assert res["verdict"] == "no-gap"
    upd = res["nominal_update"]
    rows = {r["parameter"]: r for r in upd["parameters"]}
    moved = {p for p, r in rows.items() if r["significant"]}
    # what moved is what is off, by the right amounts, and nothing else (measured: k1
    # -14.0 +- 4.7 %, c_d2 -29.6 +- 1.9 %, bearing A's clearance +26 +- 17 % for a true
    # +40 % at both bearings, just short of 2 sigma; bearing B's -0.2 +- 40 %,
    # unresolved: its journal is not measured here; the disk dampers' shares stay at 0)
    assert {"k1", "c_d2"} <= moved <= {"k1", "c_d2", "clearance", "clearance_B"}
    assert rows["c_d2"]["change"] == pytest.approx(-0.3, abs=0.05)
    assert rows["k1"]["change"] == pytest.approx(-0.15, abs=2 * rows["k1"]["std"])
    assert abs(rows["clearance"]["change"] - 0.4) < 2 * rows["clearance"]["std"]
    assert upd["mismatch_1x"]["after"] < 0.1 * upd["mismatch_1x"]["before"]

    off = diagnose(measured, candidates=(), settings=replace(DiagnosisSettings(),
                                                             update_nominal=False))
    assert off["nominal_update"] is None
    # without the update the gap stays well above the floor
    assert off["gap_before"]["per_feature"] > 2 * off["settings"]["no_gap_per_feature"]
    assert off["verdict"] == "unexplained"


@pytest.mark.slow
def test_each_probe_has_its_own_runout_with_a_2x_and_it_is_found_per_probe():
    """A shared runout vector could not fit probes that each see their own track (the
    issue's independent plant: runout first, then `unexplained`)."""
    from sknarx.rotor import MeasurementNoise, ProbeRunout, RotorBearingSimulator

    truth = {"xO1": (8e-6 * np.exp(0.4j), 3e-6 * np.exp(-1.0j)),
             "yO1": (5e-6 * np.exp(2.2j), 0j),
             "xA": (12e-6 * np.exp(-2.0j), 4e-6 * np.exp(0.5j)),
             "yA": (3e-6 * np.exp(1.0j), 2e-6 * np.exp(2.5j))}
    sim = RotorBearingSimulator(effects=[ProbeRunout(vectors=truth),
                                         MeasurementNoise(snr_db=35)], seed=4)
    speeds = list(np.linspace(81.7, 276.5, 10).round(4))
    tab = sim.sweep(speeds, fs=1000.0, n_samples=1000, settle=0.0, progress=False)
    measured = tab[["speed", "t", *truth]]
    # a crack's 2x is the alternative a per-probe 2x must win against
    d = diagnose(measured, candidates=("runout", "crack"))
    assert d["verdict"] == "runout", [(r["effect"], r["shrink"]) for r in d["ranking"]]
    assert d["shrink"] > 0.8
    # the crack's stations, each converged, are reported with their held-out excess,
    # best first (the one its parameters belong to)
    crack = next(r for r in d["ranking"] if r["effect"] == "crack")
    rows = crack["discrete_settings"]
    assert sorted(r["setting"]["crack"]["station"] for r in rows) == ["A-O1", "O2-B", "joint"]
    assert rows[0]["setting"]["crack"]["station"] == crack["params"]["station"]
    assert rows[0]["heldout_gap_after"] == crack["heldout_gap_after"]
    assert [r["heldout_gap_after"] for r in rows] == sorted(r["heldout_gap_after"] for r in rows)
    # ... with how often the held-out speeds prefer the chosen station to each other one
    assert "chosen_preferred_share" not in rows[0]
    assert all(0.0 <= r["chosen_preferred_share"] <= 1.0 for r in rows[1:])
    assert crack["setting_decided"] == (min(r["chosen_preferred_share"] for r in rows[1:])
                                        >= d["settings"]["decided_setting_support"])
    for ch, vecs in truth.items():
        est = d["ranking"][0]["params"][ch]
        # a constant vector is told apart from the rotor's own 1x only as well as the
        # rotor is known: at the journals (1x up to 23 um) to 0.01 um, at the disks (1x
        # up to 1 mm, model-form tolerance 1 % = 10 um) to 1.4 um (measured)
        tol = 2e-6 if ch.endswith("O1") else 2e-7
        for k, v in zip(("1x", "2x"), vecs, strict=True):
            got = est[f"{k}_m"] * np.exp(1j * np.radians(est[f"{k}_deg"]))
            assert abs(got - v) < tol, (ch, k, got, v, tol)


def _fit_one_effect(effect, channels, n_speeds, seed, name, n_probe=16,
                    probes_per_parameter=None):
    """Simulate a sweep with ``effect`` (SNR 35 dB) and calibrate the library's ``name``
    on it, after the nuisance-only fit (``n_probe`` Sobol settings scored first, at most
    ``probes_per_parameter`` each); returns the fitted effect parameters."""
    from sknarx.gap.calibration import calibrate
    from sknarx.rotor import EFFECTS, MeasurementNoise, RotorBearingSimulator

    sim = RotorBearingSimulator(effects=[effect, MeasurementNoise(snr_db=35)], seed=seed)
    speeds = list(np.linspace(81.7, 276.5, n_speeds).round(4))
    tab = sim.sweep(speeds, fs=1000.0, n_samples=1000, settle=0.0, progress=False)
    model, meas, train, _ = _calibration_setup(tab[["speed", "t", *channels]])
    cal0 = calibrate(model, meas, train, (), max_nfev=15)
    return calibrate(model, meas, train, [EFFECTS[name]], starts=[cal0.x],
                     max_nfev=15, n_probe=n_probe,
                     probes_per_parameter=probes_per_parameter).effect_params[0]


@pytest.mark.slow
@pytest.mark.parametrize("station", ["O2-B"])
def test_a_crack_is_found_at_its_station(station):
    """The crack's station (segment A-O1, the joint with the shaft through it, segment
    O2-B) is searched as a discrete parameter, and found. (A-O1: the test above. A crack
    through the joint is not testable on this rotor: the joint is ~300 times stiffer
    than a segment, and losing half of it moves the 2x at O1 by < 0.1 um.)"""
    from sknarx.gap import DiagnosisSettings
    from sknarx.rotor import BreathingCrack

    # the diagnosis's probes (64 for its four parameters): with where it opens searched
    # too, 16 settings left the O2-B basin unprobed and A-O1 came out cheapest in training
    settings = DiagnosisSettings()
    got = _fit_one_effect(BreathingCrack(depth=0.5, angle=0.6, station=station),
                          ("xO1", "yO1", "xA", "yA"), 10, 2, "crack",
                          n_probe=settings.n_probe,
                          probes_per_parameter=settings.probes_per_parameter)
    assert got["station"] == station
    assert got["depth"] == pytest.approx(0.5, rel=0.25)
    # (angle, opening) and (angle + pi, opening + pi) are one crack: the normal's sign
    # changes nothing but the side it opens on, which turns with it
    turn = np.pi if abs(np.angle(np.exp(1j * (got["angle"] - 0.6)))) > np.pi / 2 else 0.0
    assert abs(np.angle(np.exp(1j * (got["angle"] - turn - 0.6)))) < 0.3
    assert abs(np.angle(np.exp(1j * (got["opening"] - turn - np.pi / 2)))) < 0.3


@pytest.mark.slow
def test_a_loose_joint_is_found_with_its_opening():
    """A joint that keeps 1 % of its stiffness past a 2 um opening: the opening is found
    to a few tenths of a micrometre, the residual only as 'next to nothing' -- past the
    opening the halves are as good as cut whether 1 % or 0.1 % is left (measured: gap
    2.2 um, residual 0.0004)."""
    from sknarx.rotor import JointLooseness

    got = _fit_one_effect(JointLooseness(residual=0.01, gap=2e-6),
                          ("xO1", "yO1", "xA", "yA"), 8, 5, "looseness")
    assert got["gap"] == pytest.approx(2e-6, rel=0.25)
    assert got["residual"] < 0.05


@pytest.mark.slow
def test_a_speed_ripple_is_found_with_its_phase():
    """Where the ripple stands when each record starts is searched with its amplitude
    and frequency: held at a phase it does not have, a fit moves the frequency to make up
    for it. A 3 Hz ripple starting each record at 2 rad: frequency, amplitude and the
    ripple's phase where the records are compared (their steady half, 0.5-1 s) found.
    The phase at t = 0 trades with the frequency over that window (measured: 1.76 rad at
    3.04 Hz, which is 0.06 rad off at the window's middle; amplitude 0.0202)."""
    from sknarx.rotor import SpeedFluctuation

    true = SpeedFluctuation(amplitude=0.02, frequency=3.0, phase=2.0)
    got = _fit_one_effect(true, ("xO1", "yO1", "xA", "yA"), 6, 3, "speed-fluctuation")
    mid = 0.75  # s, the middle of the compared window

    def at_mid(p):
        return p["phase"] + 2 * np.pi * p["frequency"] * mid

    off = at_mid(got) - at_mid({"phase": true.phase, "frequency": true.frequency})
    assert abs(np.angle(np.exp(1j * off))) < 0.2
    assert got["frequency"] == pytest.approx(3.0, rel=0.03)
    assert got["amplitude"] == pytest.approx(0.02, rel=0.1)


@pytest.mark.slow
def test_misalignment_is_found_at_the_bearing_end_it_acts_on():
    from sknarx.rotor import Misalignment

    got = _fit_one_effect(Misalignment(parallel=4e-4, at="B"), ("xO1", "yO1", "xB", "yB"),
                          8, 5, "misalignment")
    assert got["at"] == "B"
    assert got["parallel"] == pytest.approx(4e-4, rel=0.25)
    assert got["lever"] < 0.25  # at the bearing, as simulated


@pytest.mark.slow
def test_a_misalignment_reaction_pair_is_found_with_its_end_and_offset():
    """The reaction as a pair across the coupling's segment (lever 1, a flexible element
    in the shaft line): most of it acts on the disk next to the coupled end, and only the
    journals tell which end -- with xO1, yO1, xB, yB alone the B-end fit stopped in a
    poorer basin (cost 2095 against A's 1165); with both journals read it is found."""
    from sknarx.rotor import Misalignment

    got = _fit_one_effect(Misalignment(parallel=4e-4, at="B", lever=1.0),
                          ("xO1", "yO1", "xA", "yA", "xB", "yB"), 8, 5, "misalignment")
    assert got["at"] == "B"
    assert got["parallel"] == pytest.approx(4e-4, rel=0.25)
    assert got["lever"] > 0.75


def test_misalignment_reaction_pair_pushes_the_next_disk_opposite_to_the_journal():
    from sknarx.rotor import Misalignment
    from sknarx.rotor.effects import EffectContext

    ctx = EffectContext(q_static=np.zeros(12))
    idx = ctx.dof_index
    for at, disk in (("A", "O1"), ("B", "O2")):
        forces = []
        for lever in (0.0, 0.4):
            kernel, p = Misalignment(parallel=3e-4, direction=0.7, phase=0.2, whirl=0.5,
                                     lever=lever, at=at).force_kernel(ctx)
            out = np.zeros(12)
            kernel(0.01, 1.3, 150.0, 0.0, np.zeros(12), np.zeros(12), p, out)
            forces.append(out)
        bare, paired = forces
        assert bare[idx["x" + disk]] == 0.0 and bare[idx["y" + disk]] == 0.0
        np.testing.assert_array_equal(paired[[idx["x" + at], idx["y" + at]]],
                                      bare[[idx["x" + at], idx["y" + at]]])
        np.testing.assert_allclose(paired[[idx["x" + disk], idx["y" + disk]]],
                                   -0.4 * bare[[idx["x" + at], idx["y" + at]]])
    with pytest.raises(ValueError, match="lever"):
        Misalignment(lever=1.5)


def _looseness_force(effect, q):
    from sknarx.rotor import RotorParameters
    from sknarx.rotor.effects import EffectContext

    kernel, p = effect.force_kernel(EffectContext(q_static=np.zeros(12),
                                                  params=RotorParameters()))
    out = np.zeros(12)
    kernel(0.0, 0.0, 150.0, 0.0, q, np.zeros(12), p, out)
    return out


def test_a_loose_joint_gives_back_the_stiffness_of_the_joint_and_the_shaft_through_it():
    """Opened from the start (gap 0), the loosening takes the share ``1 - residual`` of
    all the stiffness that ties the disks together -- the contact's ``kb``, ``k_theta``
    and the shaft element through the joint -- sample for sample what the linear
    matrices hold; closed, nothing; just past the opening, next to nothing."""
    from sknarx.rotor import JointLooseness, RotorParameters
    from sknarx.rotor.matrices import assemble
    from sknarx.rotor.parameters import DOF_NAMES

    b = RotorParameters()
    # the matrices are linear in k, kb, k_theta: the joint's share is the difference
    K_joint = assemble(b).K - assemble(b.replace(k=1e-9, kb=1e-9, k_theta=1e-9)).K
    q = np.random.default_rng(0).normal(size=12) * 1e-5
    for residual in (0.0, 0.2):
        got = _looseness_force(JointLooseness(residual=residual, gap=0.0), q)
        np.testing.assert_allclose(got, (1 - residual) * K_joint @ q,
                                   atol=1e-12 * np.abs(K_joint @ q).max())
    # the joint's radial opening for this q, then a gap just above and just below it
    idx = {n: i for i, n in enumerate(DOF_NAMES)}
    d = b.a2 - b.a1
    ux = q[idx["xO2"]] - q[idx["xO1"]] - d / 2 * (q[idx["tyO1"]] + q[idx["tyO2"]])
    uy = q[idx["yO2"]] - q[idx["yO1"]] + d / 2 * (q[idx["txO1"]] + q[idx["txO2"]])
    u = np.hypot(ux, uy)
    assert not _looseness_force(JointLooseness(residual=0.0, gap=1.001 * u), q).any()
    near = _looseness_force(JointLooseness(residual=0.0, gap=0.999 * u), q)
    assert np.abs(near).max() < 2e-3 * np.abs(K_joint @ q).max()


@given(st.floats(-np.pi, np.pi), st.floats(0.0, 2e-5))
def test_a_loose_joint_has_no_preferred_direction(angle, gap):
    """The interface is a circle: turning the rotor's state about the shaft axis turns
    the loosening's force with it (a per-plane opening would not)."""
    from sknarx.rotor import JointLooseness

    q = np.random.default_rng(1).normal(size=12) * 1e-5
    c, s = np.cos(angle), np.sin(angle)
    R = np.eye(12)
    for i in (0, 2, 4, 6, 8, 10):  # (x, y) and (tx, ty) pairs turn alike
        R[i:i + 2, i:i + 2] = [[c, -s], [s, c]]
    eff = JointLooseness(residual=0.05, gap=gap)
    f, f_turned = _looseness_force(eff, q), _looseness_force(eff, R @ q)
    np.testing.assert_allclose(f_turned, R @ f, atol=1e-9 * max(np.abs(f).max(), 1e-30))


def test_a_partner_solved_in_closed_form_is_scored_without_a_local_run():
    """Pair probing (max_nfev=0) with a partner that has nothing to probe -- the
    per-probe runout -- scores the start instead of asking least_squares for 0 steps."""
    from sknarx.gap.calibration import calibrate
    from sknarx.rotor import EFFECTS

    measured, _ = make_trial("runout", 3, speeds=SPEEDS[:4], n_samples=600)
    model, meas, train, channels = _calibration_setup(measured)
    cal0 = calibrate(model, meas, train, (), max_nfev=3)
    lead_x = np.r_[cal0.x, 0.05, 0.0]  # nuisances, then a small crack (depth, angle)
    probe = calibrate(model, meas, train, [EFFECTS["crack"], EFFECTS["runout"]],
                      starts=[lead_x], max_nfev=0, probe_from=len(lead_x),
                      fixed=[{"station": "A-O1"}, None])
    assert np.isfinite(probe.cost) and probe.cost < cal0.cost  # the runout is solved
    assert set(probe.effect_params[1]["vectors"]) == set(channels)


def test_basins_are_ranked_in_the_channel_basis_and_converged_in_the_whirl_basis(
        monkeypatch):
    """With a probe pair's whirl compared (a ``whirl_tol`` column), a calibration's
    probes are scored in both bases from one simulation, its short runs rank basins in
    the channel basis and its converged run is the whirl basis's; a probes-only score
    (a partner's) is the whirl basis's. Without the column: one basis throughout."""
    import sknarx.gap.calibration as cal_mod
    from sknarx.rotor import EFFECTS

    measured, _ = make_trial("rub", 3, speeds=SPEEDS[:4], n_samples=600)
    model, meas, train, _ = _calibration_setup(measured)
    cal0 = cal_mod.calibrate(model, meas, train, (), max_nfev=2)
    kw = {"starts": [cal0.x], "n_probe": 4, "n_short": 2}
    calls = []
    real = cal_mod.fast_residual

    def spy(*a, whirl=None, **k):
        calls.append(whirl is not None)
        return real(*a, whirl=whirl, **k)

    monkeypatch.setattr(cal_mod, "fast_residual", spy)
    strict = meas.assign(whirl_tol=0.0)
    cache = {}
    probe = cal_mod.calibrate(model, strict, train, [EFFECTS["rub"]], max_nfev=0,
                              probe_cache=cache, **kw)
    assert {len(v) for v in cache.values()} == {2}
    assert probe.cost == min(v[0] for v in cache.values())  # the whirl basis's
    assert calls == [True, False] * len(calls[::2])  # one simulation, both bases
    calls.clear()
    fit = cal_mod.calibrate(model, strict, train, [EFFECTS["rub"]], max_nfev=4, **kw)
    n_probe_calls = 2 * 5 * len(EFFECTS["rub"].discrete["at"])  # 4 probes + the start
    short, final = calls[n_probe_calls:], []
    while short and short[-1]:
        final.append(short.pop())
    assert final and short and not any(short)  # channel-basis short runs, then whirl
    assert np.isfinite(fit.cost)
    calls.clear()
    cache = {}
    cal_mod.calibrate(model, meas, train, [EFFECTS["rub"]], max_nfev=0, probe_cache=cache,
                      **kw)
    assert {len(v) for v in cache.values()} == {1} and not any(calls)


def test_each_discrete_setting_is_converged_and_offered_to_the_caller():
    """A crack's stations are not chosen by a three-iteration short run: each station's
    best short run is converged and, with ``each_discrete``, every one is returned (the
    diagnosis chooses among them on the held-out speeds); without it the lowest
    converged training cost is the calibration."""
    from sknarx.gap.calibration import calibrate
    from sknarx.rotor import EFFECTS

    measured, _ = make_trial("crack", 5, speeds=SPEEDS[:4], n_samples=600)
    model, meas, train, _ = _calibration_setup(measured)
    cal0 = calibrate(model, meas, train, (), max_nfev=3)
    kw = {"starts": [cal0.x], "max_nfev": 4, "n_probe": 4, "n_short": 1}
    each = calibrate(model, meas, train, [EFFECTS["crack"]], each_discrete=True, **kw)
    assert sorted(c.effect_params[0]["station"] for c in each) == sorted(EFFECTS["crack"].STATIONS)
    assert all(np.isfinite(c.cost) and c.cost <= cal0.cost * 1.01 for c in each)
    one = calibrate(model, meas, train, [EFFECTS["crack"]], **kw)
    assert one.cost == pytest.approx(min(c.cost for c in each))


def test_the_diagnosis_integrates_at_its_own_step_factor():
    """Every sweep the diagnosis runs uses ``DiagnosisSettings.step_factor``: four RK-4
    steps per 1 kHz sample on the paper rotor at 2.5, against the simulator's five."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.calibration import SweepModel
    from sknarx.rotor import RotorParameters

    nuis = np.array([1.0, 0.0, 1.0, 1.0])
    steps = {}
    for factor in (2.0, DiagnosisSettings().step_factor):
        model = SweepModel(base=RotorParameters(), fs=1000.0, n_samples=100,
                           channels=("xO1",), step_factor=factor)
        sim = model._simulator(nuis, (), [276.5])
        assert sim.step_factor == factor
        steps[factor] = sim.substeps(1000.0, 276.5)
    assert steps == {2.0: 5, 2.5: 4}


def test_probes_scale_with_the_number_of_probed_parameters():
    """A two-parameter clearance gets 32 probes, a four-parameter crack the full 64
    (per station), each with the start itself: the probe cache holds one cost each."""
    from sknarx.gap.calibration import calibrate
    from sknarx.rotor import EFFECTS

    measured, _ = make_trial("clearance", 2, speeds=SPEEDS[:4], n_samples=400)
    model, meas, train, _ = _calibration_setup(measured)
    cal0 = calibrate(model, meas, train, (), max_nfev=2)
    for name, expected in (("clearance", 32 + 1), ("crack", 3 * (64 + 1))):
        cache = {}
        calibrate(model, meas, train, [EFFECTS[name]], starts=[cal0.x], max_nfev=0,
                  n_probe=64, probes_per_parameter=16, probe_cache=cache)
        assert len(cache) == expected, name
    cache = {}
    calibrate(model, meas, train, [EFFECTS["clearance"]], starts=[cal0.x], max_nfev=0,
              n_probe=64, probe_cache=cache)
    assert len(cache) == 64 + 1  # without the cap: whatever the dimension


def test_a_pairs_partner_is_probed_and_fitted_at_the_pair_settings(monkeypatch):
    """Partners are probed on top of the lead's fit with ``pair_probes_per_parameter``
    per searched parameter, rounded up to a power of two, and the start (a
    two-parameter clearance or looseness: 16 and the start), and the pair's fit starts
    ``pair_short_starts`` short runs per discrete setting; the pair reuses its
    partner's probes."""
    import math
    from types import SimpleNamespace

    from sknarx.gap import DiagnosisSettings
    from sknarx.gap import diagnosis as dg
    from sknarx.gap.calibration import calibrate
    from sknarx.gap.checkpoint import NoCheckpoint
    from sknarx.rotor import EFFECTS

    def probes(name):  # the partner's probes and its start
        return 2 ** math.ceil(math.log2(8 * len(EFFECTS[name].bounds))) + 1

    assert probes("clearance") == probes("looseness") == 16 + 1
    measured, _ = make_trial("clearance", 2, speeds=SPEEDS[:4], n_samples=400)
    model, meas, train, _ = _calibration_setup(measured)
    cal0 = calibrate(model, meas, train, (), max_nfev=2)
    lead_cal = calibrate(model, meas, train, [EFFECTS["runout"]], starts=[cal0.x],
                         max_nfev=0)
    lead = SimpleNamespace(names=("runout",), state=lead_cal)
    settings = DiagnosisSettings(pair_probes_per_parameter=8, pair_short_starts=2)
    front = dg._SweepFrontEnd(model, meas, train, train, None, settings, cal0.x,
                              NoCheckpoint())
    front.partners(lead, ["clearance"], 1)
    assert len(front._probe_costs) == probes("clearance")
    front.partners(lead, ["looseness"], 1)
    both = probes("clearance") + probes("looseness")
    assert len(front._probe_costs) == both
    seen = []

    def spy(*args, **kw):
        seen.append(kw)
        return calibrate(*args, **{**kw, "max_nfev": 0})

    monkeypatch.setattr(dg, "calibrate", spy)
    monkeypatch.setattr(dg, "heldout_gap", lambda *a: (1.0, None))
    front.fit_pair(lead, "clearance")
    assert len(front._probe_costs) == both  # the partner's probes, reused
    assert seen[0]["n_short"] == 2 and seen[0]["probes_per_parameter"] == 8


@given(st.integers(1, 5), st.integers(0, 2**31 - 1))
def test_the_secant_jacobian_of_an_affine_residual_is_exact_at_every_step(refresh, seed):
    """Broyden's update keeps an exact Jacobian exact on an affine residual, whatever the
    steps between differenced ones; the differenced one matches scipy's ``'2-point'``."""
    from scipy.optimize._numdiff import approx_derivative

    from sknarx.gap.jacobian import SecantJacobian

    rng = np.random.default_rng(seed)
    A, b = rng.normal(size=(7, 4)), rng.normal(size=7)
    lo, hi = -np.ones(4), np.ones(4)
    jac = SecantJacobian(lambda x: A @ x + b, lo, hi, rel_step=1e-6, refresh=refresh)
    x = rng.uniform(-0.9, 0.9, 4)
    np.testing.assert_allclose(jac(x), approx_derivative(lambda z: A @ z + b, x,
                                                        rel_step=1e-6, bounds=(lo, hi)),
                               rtol=1e-6, atol=1e-8)
    for _ in range(6):
        x = np.clip(x + rng.normal(scale=0.3, size=4), lo, hi)
        jac.residual(x)
        np.testing.assert_allclose(jac(x), A, rtol=1e-5, atol=1e-6)
    assert jac.n_differenced == -(-7 // refresh)  # the first call and every refresh-th


def test_a_difference_jacobian_evaluated_in_one_batch_is_the_same():
    """``many`` evaluates a difference Jacobian's columns in one call: the same
    Jacobians, one call per differenced Jacobian."""
    from sknarx.gap.jacobian import SecantJacobian

    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 4))

    def fun(x):
        return np.tanh(A @ x) + x[0] * x[1]

    batches = []
    lo, hi = -np.ones(4), np.ones(4)
    one = SecantJacobian(fun, lo, hi, refresh=2)
    many = SecantJacobian(fun, lo, hi, refresh=2,
                          many=lambda xs: batches.append(len(xs)) or [fun(x) for x in xs])
    x = rng.uniform(-0.9, 0.9, 4)
    for _ in range(5):
        x = np.clip(x + rng.normal(scale=0.2, size=4), lo, hi)
        one.residual(x)
        many.residual(x)
        assert np.array_equal(one(x), many(x))
    assert batches == [4] * many.n_differenced and many.n_differenced == 3


def test_a_secant_jacobian_least_squares_reaches_the_differenced_one_s_minimum():
    from scipy.optimize import least_squares

    from sknarx.gap.jacobian import SecantJacobian

    def rosenbrock(x):
        return np.array([10 * (x[1] - x[0] ** 2), 1 - x[0], 0.3 * (x[2] - x[0])])

    lo, hi = np.full(3, -2.0), np.full(3, 2.0)
    ref = least_squares(rosenbrock, [-1.2, 1.0, 0.0], bounds=(lo, hi))
    jac = SecantJacobian(rosenbrock, lo, hi, refresh=4)
    sec = least_squares(jac.residual, [-1.2, 1.0, 0.0], jac=jac, bounds=(lo, hi))
    np.testing.assert_allclose(sec.x, ref.x, atol=1e-5)
    assert jac.n_differenced < jac._calls  # the secant steps did some of the work
    with pytest.raises(ValueError, match="refresh"):
        SecantJacobian(rosenbrock, lo, hi, refresh=0)


@given(st.integers(0, 2**31 - 1))
def test_a_settled_stop_ends_within_a_small_share_of_the_uncertainty(seed):
    """A noisy exponential decay fitted from far off: the run that stops once a step
    moves no parameter by 0.1 of its standard error ends within 0.5 of each standard
    error of the fully converged fit, on fewer evaluations."""
    from scipy.optimize import least_squares

    from sknarx.gap.jacobian import SecantJacobian, SettledStop

    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 3.0, 40)
    y = 2.0 * np.exp(-1.3 * t) + 0.5 * t * np.sin(3 * t) * 0.05 + rng.normal(0, 0.05, t.size)

    def resid(x):
        return (x[0] * np.exp(-x[1] * t) + x[2] - y) / 0.05

    lo, hi = np.array([0.1, 0.05, -1.0]), np.array([10.0, 10.0, 1.0])
    x0 = np.array([6.0, 6.0, 0.5])
    full = least_squares(resid, x0, bounds=(lo, hi), x_scale=hi - lo, max_nfev=200,
                         ftol=1e-12, xtol=1e-12, gtol=1e-12)
    jac = SecantJacobian(resid, lo, hi, rel_step=1e-6, refresh=1)
    stop = SettledStop(jac, 0.1)
    evaluations = []
    early = least_squares(lambda x: evaluations.append(1) or jac.residual(x), x0, jac=jac,
                          bounds=(lo, hi), x_scale=hi - lo, max_nfev=200, callback=stop)
    J = full.jac
    sd = np.sqrt(np.diag(np.linalg.inv(J.T @ J)) * 2 * full.cost / (t.size - 3))
    assert stop.stopped
    assert np.all(np.abs(early.x - full.x) <= 0.5 * sd)
    assert len(evaluations) < full.nfev
    with pytest.raises(ValueError, match="tol"):
        SettledStop(jac, 0.0)


def test_diagnose_keeps_blas_to_one_thread_under_its_simulation_threads(monkeypatch):
    # the evaluations run their speeds on two threads; a BLAS threading its small
    # solves as well halves the throughput on two cores, whoever calls diagnose
    from threadpoolctl import threadpool_info, threadpool_limits

    import sknarx.gap.diagnosis as D

    seen = []
    monkeypatch.setattr(D, "_diagnose", lambda *a: seen.append(
        [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]))
    with threadpool_limits(limits=2, user_api="blas"):
        D.diagnose(None)
    assert seen and seen[0] and all(n == 1 for n in seen[0])


# ------------------------------------------------- how firmly a discrete setting is chosen
_speeds_excess = st.lists(st.tuples(st.floats(0, 50), st.floats(0, 50)), min_size=1,
                          max_size=12)


@given(_speeds_excess, st.integers(0, 2**16))
def test_setting_support_is_antisymmetric_and_a_share(pairs, seed):
    """The share of resamples preferring one table over another and the share preferring
    the other add to one (the tables are paired speed by speed, ties split)."""
    from sknarx.gap.core import setting_support

    speeds = np.arange(len(pairs), dtype=float)
    a = pd.DataFrame({"speed": speeds, "excess": [p[0] for p in pairs]})
    b = pd.DataFrame({"speed": speeds, "excess": [p[1] for p in pairs]})
    ab, ba = setting_support(a, b, 64, seed), setting_support(b, a, 64, seed)
    assert 0.0 <= ab <= 1.0
    assert ab + ba == pytest.approx(1.0)
    # a setting that leaves more at every speed is never preferred; a diverged one always
    worse = b.assign(excess=np.maximum(a.excess, b.excess) + 1.0)
    assert setting_support(a, worse, 64, seed) == 1.0
    assert setting_support(a, None, 64, seed) == 1.0


def test_a_setting_is_decided_only_against_every_other():
    from sknarx.gap.diagnosis import _setting_evidence

    rows = [{"setting": {"crack": {"station": "A-O1"}}},
            {"setting": {"crack": {"station": "joint"}}, "chosen_preferred_share": 0.99},
            {"setting": {"crack": {"station": "O2-B"}}, "chosen_preferred_share": 0.7}]
    assert _setting_evidence(rows, 0.95)["setting_decided"] is False
    assert _setting_evidence(rows, 0.6)["setting_decided"] is True
    assert _setting_evidence(rows[:1], 0.6)["setting_decided"] is False


def _stub_front_end(monkeypatch, setting):
    """The time-series front end with its fits stubbed out: only what it carries from
    one fit to the next is exercised."""
    from types import SimpleNamespace

    from sknarx.gap import diagnosis
    from sknarx.gap.core import CandidateFit

    monkeypatch.setattr(diagnosis, "discrete_settings", lambda state, i, cls: setting)
    monkeypatch.setattr(diagnosis, "effect_blocks", lambda x, classes: [x[:1], x[1:]])
    fe = object.__new__(diagnosis._SweepFrontEnd)
    fe._lead_x, fe._setting_fits = None, {}
    fe._calibrate = lambda names, **kw: None
    fe._result = lambda names, cal: CandidateFit(names, {}, {}, 5, 1.0, None, {}, None)

    def fit(names, details):
        return CandidateFit(names, {}, {}, 5, 2.0, None, details,
                            SimpleNamespace(x=np.zeros(len(diagnosis.NUISANCE) + 2)))
    return fe, fit


def test_a_continued_or_refitted_candidate_keeps_its_setting_evidence(monkeypatch):
    """The lead's continuation and a pair member's refit replace the first fit in the
    ranking: the evidence on its discrete setting (how firmly the held-out speeds chose
    the rub's disk) must survive, and a member whose pair moved it elsewhere is not
    decided."""
    rows = [{"setting": {"rub": {"at": "O1"}}, "heldout_gap_after": 69.0},
            {"setting": {"rub": {"at": "O2"}}, "heldout_gap_after": 80.0,
             "chosen_preferred_share": 0.9}]
    fe, fit = _stub_front_end(monkeypatch, {"at": "O1"})
    lead = fit(("rub",), {"discrete_settings": rows, "setting_decided": False})
    more = fe.continue_fit(lead)
    assert more.details["discrete_settings"] is rows
    assert more.details["setting_decided"] is False

    single = {"discrete_settings": rows, "setting_decided": True}
    fe._setting_fits[("rub",)] = {"O1": fit(("rub",), single)}
    pair = fit(("rub", "runout"), {})
    member = fe.refit_members(pair)[0]
    assert member.details["setting_decided"] is True
    fe, fit = _stub_front_end(monkeypatch, {"at": "O2"})  # the pair put the rub at O2
    fe._setting_fits[("rub",)] = {"O1": fit(("rub",), single)}
    member = fe.refit_members(fit(("rub", "runout"), {}))[0]
    assert member.details["setting_decided"] is False


def test_the_report_says_when_the_setting_is_not_decided():
    from sknarx.gap.report import _discrete_text, _undecided_text

    entry = {"discrete_settings": [
        {"setting": {"rub": {"at": "O1"}}, "heldout_gap_after": 69.2},
        {"setting": {"rub": {"at": "O2"}}, "heldout_gap_after": 79.8,
         "chosen_preferred_share": 0.875}], "setting_decided": False}
    text = _discrete_text(entry)
    assert "rub O2 79.8 (the first preferred in 88 % of resamples)" in text
    assert text.endswith("setting not decided by the data")
    doc = {"setting_decided": False, "settings": {"decided_setting_support": 0.95}}
    assert "fewer than 95 % of bootstrap resamples" in _undecided_text(doc)
    assert _undecided_text({"setting_decided": True}) == ""
    assert _undecided_text({}) == ""


def test_the_verdicts_other_settings_are_refitted_from_its_own_fit(monkeypatch):
    """A setting whose own search missed the basin the chosen one found is no evidence
    against it: refitted from the verdict's fit it reaches nearly the same held-out
    excess, and the setting is then not decided."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import CandidateFit

    fe, fit = _stub_front_end(monkeypatch, {"at": "O1"})
    fe.settings = DiagnosisSettings()
    cmp = pd.DataFrame({"speed": [1.0, 2.0, 3.0], "excess": [1.0, 1.0, 1.0]})
    rows = [{"setting": {"rub": {"at": "O1"}}, "heldout_gap_after": 3.0,
             "training_cost": 10.0},
            {"setting": {"rub": {"at": "O2"}}, "heldout_gap_after": 50.0,
             "training_cost": 40.0, "chosen_preferred_share": 1.0}]
    verdict = fit(("rub",), {"discrete_settings": rows, "setting_decided": True})
    verdict.cmp, verdict.heldout_excess = cmp, 3.0
    verdict.state.cost = 10.0
    seen = []

    def calibrate(names, **kw):
        seen.append(kw)
        return None
    fe._calibrate = calibrate
    fe._result = lambda names, cal: CandidateFit(
        names, {}, {}, 5, 3.1, cmp.assign(excess=[1.0, 1.1, 1.0]), {},
        type("State", (), {"cost": 10.5})())
    entries, better = fe.recheck_setting(verdict)
    # one refit: the other disk, held, started from the verdict's parameters
    assert len(seen) == 1 and seen[0]["fixed"] == [{"at": "O2"}]
    assert seen[0]["starts"][0] is verdict.state.x and seen[0]["n_probe"] == 0
    assert better is None  # the verdict's disk still fits best
    other = entries["discrete_settings"][1]
    assert other["from_chosen_fit"] and other["heldout_gap_after"] == 3.1
    assert other["chosen_preferred_share"] < 0.95
    assert entries["setting_decided"] is False

    # refitted from the verdict's fit, the other end does better: it replaces the fit
    fe._result = lambda names, cal: CandidateFit(
        names, {"at": "B"}, {}, 5, 1.0, cmp.assign(excess=[0.2, 0.4, 0.4]), {},
        type("State", (), {"cost": 8.0})())
    entries, better = fe.recheck_setting(verdict)
    assert better is not None and better.heldout_excess == 1.0
    rows = entries["discrete_settings"]
    assert rows[0]["from_chosen_fit"] and rows[0]["heldout_gap_after"] == 1.0
    assert rows[1]["setting"] == {"rub": {"at": "O1"}}
    assert rows[1]["chosen_preferred_share"] == 1.0 and entries["setting_decided"]


def test_a_better_setting_found_by_the_recheck_is_decided_again():
    """The core side of the recheck: the better fit replaces the verdict's in the
    ranking and the verdict is decided from the new ranking."""
    from sknarx.gap import DiagnosisSettings
    from sknarx.gap.core import CandidateFit, FrontEnd, rank, recheck_choice

    cmp0 = pd.DataFrame({"speed": [1.0, 2.0], "window": "steady", "channel": "xO1",
                         "feature": "1x", "excess": [50.0, 50.0], "z2": 52.0, "gap": 1e-6})
    first = CandidateFit(("misalignment",), {"at": "A"}, {}, 5, 40.0,
                         cmp0.assign(excess=[20.0, 20.0]),
                         {"discrete_settings": [{"setting": {}}]})
    other = CandidateFit(("crack",), {"station": "A-O1"}, {}, 3, 60.0,
                         cmp0.assign(excess=[30.0, 30.0]), {})
    better = CandidateFit(("misalignment",), {"at": "B"}, {}, 5, 10.0,
                          cmp0.assign(excess=[5.0, 5.0]), {})

    class Front(FrontEnd):
        def recheck_setting(self, fit):
            return {"discrete_settings": [], "setting_decided": True}, better

    ranked = rank([first, other], 100.0, cmp0)
    s = DiagnosisSettings()
    choice, ranked = recheck_choice(Front(), ranked[0], ranked, 100.0, cmp0, s, 2, 50.0)
    assert choice["_fit"] is better and choice["params"] == {"at": "B"}
    assert choice["setting_decided"] is True
    assert [r["params"] for r in ranked] == [{"at": "B"}, {"station": "A-O1"}]


@pytest.mark.parametrize("change, message", [
    ({"no_gap_per_feature": -0.1}, "no_gap_per_feature must be a number in [0, inf]"),
    ({"no_gap_per_feature": float("nan")}, "no_gap_per_feature must be a number in [0, inf]"),
    ({"min_shrink": float("inf")}, "min_shrink must be a finite number in (-inf, 1]"),
    ({"min_shrink": float("nan")}, "min_shrink must be a finite number"),
    ({"pass_rtol": 1.0}, "pass_rtol must be a finite number in [0, 1)"),
    ({"pair_margin": -1.0}, "pair_margin must be a finite number in [0, inf) or None"),
    ({"n_probe": 0}, "n_probe must be a finite number in [1, inf)"),
    ({"max_nfev": 7.5}, "max_nfev must be a whole number"),
    ({"update_nominal": "yes"}, "update_nominal must be True or False"),
    ({"order_floors_z2": (2.5, 1.8)}, "order_floors_z2 holds the 1x, 2x and 3x floors"),
    ({"order_floors_z2": (2.5, 0.0, 1.8)}, "order_floors_z2 (2x) must be"),
    ({"decided_setting_support": 0.0}, "decided_setting_support must be a finite number in (0, 1]"),
    ({"n_jobs": 0}, "n_jobs must not be 0"),
])
def test_a_setting_out_of_its_range_is_named_when_the_settings_are_made(change, message):
    """A settings object is read deep inside an hour-long diagnosis: a value out of its
    range fails at once, naming the field and its range."""
    with pytest.raises(ValueError, match="^DiagnosisSettings." + re.escape(message)):
        DiagnosisSettings(**change)
    with pytest.raises(ValueError, match="^DiagnosisSettings."):
        replace(DiagnosisSettings(), **change)


@given(st.fixed_dictionaries({
    "no_gap_per_feature": st.floats(0.0, 10.0), "min_shrink": st.floats(-1.0, 1.0),
    "pass_rtol": st.floats(0.0, 0.99), "n_probe": st.integers(1, 1024),
    "pair_margin": st.none() | st.floats(0.0, 100.0),
    "order_floors_z2": st.none() | st.tuples(*[st.floats(0.01, 10.0)] * 3)}))
def test_every_setting_in_its_range_is_accepted(change):
    assert replace(DiagnosisSettings(), **change).n_probe == change["n_probe"]


def test_an_infinite_no_gap_floor_is_a_setting():
    """A floor no sweep is over (every sweep within it) is how the blind benchmark's
    effect-free trials measure the gap before any effect; the check once refused it, and
    every blind run failed at its first trial."""
    assert DiagnosisSettings(no_gap_per_feature=math.inf).no_gap_per_feature == math.inf


def test_every_setting_has_its_range_checked():
    """A field added to DiagnosisSettings without a range would go unchecked."""
    from dataclasses import fields

    from sknarx.gap import settings as mod

    checked = set(mod._RANGES) | set(mod._FLAGS) | {"order_floors_z2"}
    assert {f.name for f in fields(DiagnosisSettings)} == checked
    assert set(mod._INTEGERS) <= set(mod._RANGES)


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


def _measured_entry(names, E0, E, log_shrink=0.5):
    """A ranking entry that carries its gap before, as :func:`sknarx.gap.core.rank`
    makes them."""
    return {**_entry(names, E, 1.0 - E / E0, log_shrink), "heldout_gap_before": E0}


def test_the_verdict_judges_the_share_of_the_gap_above_the_effect_free_noise():
    """Under the floor the effect-free noise (0.112 a feature) is about half the gap: an
    anisotropy that removes 40 % of a 0.25-per-feature gap removes 72 % of what is above
    the noise, and is named (docs/gap_validation.md, *The noise-referenced shrink made the
    package's rule*); with the plain share, or where the gap is not above the noise, the
    verdict is as before."""
    from sknarx.gap.core import conclude, decide, judged_shrink, shortfalls
    from sknarx.gap.report import closest_text

    s = DiagnosisSettings()
    n = 240
    E0 = 0.25 * n
    mild = _measured_entry(["anisotropy"], E0, 0.6 * E0)
    assert judged_shrink(mild, s, n) == pytest.approx(0.4 * 0.25 / (0.25 - 0.112))
    assert shortfalls(mild, s, n, under=True) == []
    assert decide(0.25, [mild], s, n) is mild
    plain = replace(s, noise_per_feature=None)
    assert judged_shrink(mild, plain, n) == mild["shrink"]
    assert decide(0.25, [mild], plain, n) == "no-gap"
    # a gap not above the noise, or an entry without its gap before: the plain share
    quiet = _measured_entry(["clearance"], 0.1 * n, 0.05 * n)
    assert judged_shrink(quiet, s, n) == quiet["shrink"]
    bare = _entry(["rub"], 10.0, 0.3, 0.5)
    assert judged_shrink(bare, s, n) == 0.3
    # the document says both shares
    cmp0 = pd.DataFrame({"excess": [1.0], "z2": [2.0], "speed": [100.0], "gap": [1e-6],
                         "window": ["steady"], "channel": ["xA"], "feature": ["1x"]})
    doc = conclude(None, [mild], cmp0, [], plain, n)
    assert doc["closest"]["shrink_above_noise"] == pytest.approx(doc["closest"]["shrink"])
    text = closest_text({"closest": {**doc["closest"], "shrink_above_noise": 0.55}})
    assert "removes 40 % of the held-out gap (55 % of what is above the effect-free " \
           "noise), where a named effect needs 60 % of that." in text
    # just above the noise a sweep's own noise can be under the median: more than all
    text = closest_text({"closest": {**doc["closest"], "shrink_above_noise": 1.4}})
    assert "(more than all of what is above the effect-free noise)" in text


@given(st.floats(1.0, 1e4), st.floats(0.0, 1.0), st.floats(0.0, 0.5), st.integers(1, 500))
def test_the_share_above_the_noise_is_never_below_the_plain_share(E0, kept, m0, n):
    """Taking the noise out of the gap can only raise what a candidate that removes
    anything is credited with (and never credits one that removes nothing)."""
    from sknarx.gap.core import judged_shrink

    entry = _measured_entry(["crack"], E0, kept * E0)
    share = judged_shrink(entry, replace(DiagnosisSettings(), noise_per_feature=m0), n)
    assert share >= entry["shrink"] - 1e-12
    if kept == 1.0:
        assert share == pytest.approx(0.0, abs=1e-12)
