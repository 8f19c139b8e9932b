"""Gap diagnosis: features, gap map, file checks, and a fast blind subset end to end."""

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from sknarx.gap import compare, diagnose, order_features
from sknarx.gap.measured import check_measured
from sknarx.gap.synthetic import make_trial

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


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d.drop(columns="t"), "lack column"),
        (lambda d: d.assign(xO1=d.xO1 * 1e6), "implausible"),
        (lambda d: d.assign(xO1=np.where(d.index == 5, np.nan, d.xO1)), "NaN"),
        (lambda d: d[d.speed < 150], "at least 4"),
        (lambda d: d.rename(columns={"xO1": "probe1"}), "No measured channel"),
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
    est = d["ranking"][0]["params"]["amplitude"]
    assert abs(est / truth["effects"][0]["amplitude"] - 1) < 0.2
    assert d["where"] and d["where"][0]["order"] == "1x"


def test_blind_subset_says_no_gap_on_effect_free_data():
    measured, _ = make_trial(None, 11, speeds=SPEEDS, n_samples=1000)
    d = diagnose(measured, candidates=("runout", "crack"))
    assert d["verdict"] == "no-gap"


def test_gap_command_writes_diagnosis(runout_trial, tmp_path):
    measured, _ = runout_trial
    path = tmp_path / "measured.csv"
    measured.to_csv(path, index=False)
    res = subprocess.run([sys.executable, "-m", "sknarx", "gap", "--measured", str(path),
                          "--out", str(tmp_path / "out"), "--candidates", "runout", "crack",
                          "--quiet"], capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    doc = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    for key in ("verdict", "ranking", "where", "shrink"):
        assert key in doc
    r0 = doc["ranking"][0]
    for key in ("effect", "params", "heldout_gap_before", "heldout_gap_after", "shrink",
                "evidence"):
        assert key in r0
    assert {"speed_range", "order", "channel", "share"} <= set(doc["where"][0])
    assert "narx" in doc and doc["narx"]["terms_measured"]
    assert (tmp_path / "out" / "report.html").exists()
    assert (tmp_path / "out" / "gap_map.png").exists()
