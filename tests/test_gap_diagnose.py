"""The time-series diagnosis end to end: verdicts, effects found, the command."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx.gap import SearchBudget, check_measured, diagnose, order_features
from sknarx.testing import make_trial

SPEEDS = tuple(np.linspace(81.7, 276.5, 6).round(4))


@pytest.fixture(scope="module")
def runout_trial():
    return make_trial("runout", 7, speeds=SPEEDS, n_samples=1000)


def test_blind_subset_finds_withheld_runout(capsys):
    """examples/04_gap_diagnosis.py, run here (not again with the other examples)."""
    import runpy
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "examples" / "04_gap_diagnosis.py"
    ns = runpy.run_path(str(example), run_name="__main__")
    measured, truth, d = ns["measured"], ns["truth"], ns["result"]
    assert "verdict: runout" in capsys.readouterr().out
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
    # within the floor the candidates are still searched, and none passes the rule's
    # tests of what is left on an effect-free sweep; the document says what the gap per
    # feature was divided by and the floor the sweep's own noise set (docs/gap.md)
    n = d["n_heldout_features"]
    floor = d["gap_before"]["floor"]
    assert d["gap_before"]["per_feature"] < floor["floor_per_feature"] and n > 0
    assert floor["noise_per_feature"] < floor["floor_per_feature"]
    assert floor["false_alarm"] == d["settings"]["rule"]["false_alarm"]
    assert {r["effect"] for r in d["ranking"] if isinstance(r["effect"], str)} == {
        "runout", "crack"}
    assert d["gap_before"]["per_feature"] * n == pytest.approx(d["gap_before"]["heldout_excess"])
    assert d.verdict.outcome == "no-gap" and d.verdict.within_floor


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
    # Ctrl-C as at a terminal: a test worker may ignore SIGINT, and a Python started
    # with SIGINT ignored keeps ignoring it
    first = subprocess.Popen(command + ["--quiet"], stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
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
    # each shaft order's held-out mean z2, and the floor the sweep's noise set
    by_order = doc["gap_before"]["by_order"]
    assert {"1x", "2x", "3x"} <= set(by_order) and all(r["n"] > 0 for r in by_order.values())
    floor = doc["gap_before"]["floor"]["floor_per_feature"]
    assert "narx" in doc and doc["narx"]["terms_measured"]
    from html import unescape

    html = unescape((tmp_path / "out" / "report.html").read_text())
    assert f"{floor:.3g} that the sweep's own noise leaves at the 99 % level" in html
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
    from sknarx.orders import TRANSIENT_RATIO, free_response_decay

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
    floor = res["gap_before"]["floor"]
    assert res["gap_before"]["per_feature"] < floor["floor_per_feature"]
    assert res["verdict"] == "no-gap"


@pytest.mark.slow
def test_an_effect_free_sweep_of_a_mismatched_rotor_is_no_gap_with_the_updates_listed():
    """Segment stiffness, a damper, a bearing damper and the clearance off by 15-40 %:
    four global scalars cannot absorb that (the gap stays several times the floor, and
    the full library then called it `unexplained`); the nominal update does, and says
    what."""

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

    off = diagnose(measured, candidates=(), update=False)
    assert off["nominal_update"] is None
    # without the update the gap stays well above the floor
    assert off["gap_before"]["per_feature"] > 2 * off["gap_before"]["floor"]["floor_per_feature"]
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
                                        >= 1 - d["settings"]["rule"]["false_alarm"])
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
    from sknarx.gap.sweep_model import SweepModel
    from sknarx.rotor import EFFECTS, MeasurementNoise, RotorBearingSimulator, RotorParameters

    sim = RotorBearingSimulator(effects=[effect, MeasurementNoise(snr_db=35)], seed=seed)
    speeds = list(np.linspace(81.7, 276.5, n_speeds).round(4))
    tab = sim.sweep(speeds, fs=1000.0, n_samples=1000, settle=0.0, progress=False)
    measured, info = check_measured(tab[["speed", "t", *channels]], None)
    model = SweepModel(base=RotorParameters(), fs=info["fs"], n_samples=info["n_samples"],
                       channels=tuple(info["channels"]))
    train = np.array(info["speeds"])[0::2]
    meas = order_features(measured, info["channels"], 0.5)
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
    from sknarx.rotor import BreathingCrack

    # the diagnosis's probes (64 for its four parameters): with where it opens searched
    # too, 16 settings left the O2-B basin unprobed and A-O1 came out cheapest in training
    settings = SearchBudget()
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
