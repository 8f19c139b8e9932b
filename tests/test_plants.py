"""The independent plants of the blind benchmark, and the diagnosis on them (fast subset).

The plants live in ``validation/plants`` (they are test equipment, not the package):
a second derivation of the paper's rotor and the ROSS finite-element plant. These
tests check that each is the rotor it claims to be, that its faults leave their
signatures, and that the nominal update stays physical on a plant written from other
readings of the paper and finds where its dampers act (the diagnosis end to end on
them: ``test_plants_diagnosis.py``).
"""

import warnings

import numpy as np
import pytest

from sknarx.orders import harmonic_basis
from validation.plants.families import (
    CHANNELS,
    SPEEDS,
    _own_sweep,
    draw_trial,
    make_family_trial,
    simulate,
)
from validation.plants.second_derivation import SecondDerivationPlant, SecondRotor


def _orders(t, x, w, k):
    """Complex k-th shaft order of a record (m)."""
    B = harmonic_basis(w * np.asarray(t), [1.0, 2.0, 3.0])
    c = np.linalg.lstsq(B, np.asarray(x), rcond=None)[0]
    i = 1 + 2 * [1.0, 2.0, 3.0].index(k)
    return c[i] - 1j * c[i + 1]


def test_second_derivation_peaks_where_the_paper_puts_its_critical_speed():
    plant = SecondDerivationPlant()
    speeds = np.array([100.0, 125.0, 140.0, 150.0, 165.0, 200.0])
    amp = [abs(_orders(r["t"], r["xO1"], w, 1.0))
           for w, r in ((w, plant.run(w, n_samples=500, settle=1.0)) for w in speeds)]
    peak = speeds[int(np.argmax(amp))]
    # the paper: 144.5 rad/s; this reading (absolute disk damping, tilt damping) moves
    # the peak a little, not out of the band
    assert 125.0 <= peak <= 165.0
    assert 0.5e-3 < max(amp) < 2e-3


def test_second_derivation_probes_on_housings_read_relative_motion():
    rotor = SecondRotor()
    # 5e9 N/m: as rigid as the 10 kHz Runge-Kutta step allows
    stiff = SecondDerivationPlant(SecondRotor(k_px=5e9, k_py=5e9)).run(150.0, n_samples=400)
    soft = SecondDerivationPlant(rotor).run(150.0, n_samples=400)
    # on stiffer pedestals the housing moves less and the journal probe reads more of the
    # journal's motion; on the 1e9 N/m pedestals the relative reading is smaller
    assert abs(_orders(soft["t"], soft["xA"], 150.0, 1.0)) < abs(
        _orders(stiff["t"], stiff["xA"], 150.0, 1.0))


def test_second_derivation_crack_raises_the_two_x():
    rotor = SecondRotor()
    free = SecondDerivationPlant(rotor).run(120.0, n_samples=1000)
    rotor.effects = {"crack": [0, 0.4, 0.1, 0.0]}
    cracked = SecondDerivationPlant(rotor).run(120.0, n_samples=1000)
    two_free = abs(_orders(free["t"], free["xO1"], 120.0, 2.0))
    two_crack = abs(_orders(cracked["t"], cracked["xO1"], 120.0, 2.0))
    assert two_crack > 5 * two_free


def test_second_derivation_cage_fault_is_a_line_at_the_cage_order_on_its_bearing():
    # the out-of-library cage fault must show where a probe can see it: at the cage's
    # order (r_inner / (R_outer + r_inner), about 0.39x), on the journal it acts on
    rotor, w = SecondRotor(), 150.0
    order = rotor.r_inner / (rotor.R_outer + rotor.r_inner)

    def line(rec, ch):
        B = harmonic_basis(w * np.asarray(rec["t"]), [order, 1.0])
        c = np.linalg.lstsq(B, np.asarray(rec[ch]), rcond=None)[0]
        return abs(c[1] - 1j * c[2])

    free = SecondDerivationPlant(rotor).run(w, n_samples=1000)
    rotor.effects = {"cage-fault": [0, 50.0, 0.3]}  # at bearing A, 50 N
    faulty = SecondDerivationPlant(rotor).run(w, n_samples=1000)
    assert line(faulty, "xA") > 10 * line(free, "xA")
    assert line(faulty, "xA") > 2 * line(faulty, "xB")


def test_trials_are_the_same_draw_for_every_family_but_their_own_stream():
    a, b = draw_trial("crack", 7, "own"), draw_trial("crack", 7, "own")
    assert a == b
    c = draw_trial("crack", 7, "second")
    assert c["kind"] == "crack" and c["effects"]["crack"] != a["effects"]["crack"]


def test_the_thermal_bow_relaxes_step_by_step(monkeypatch):
    # each step is the plant with that step's bow, settled on its own: the relaxing bow
    # is what keeps it out of the library (a fixed one is runout plus unbalance);
    # three of the steps, settled 0.1 s, keep the test short
    from validation.plants import families

    monkeypatch.setattr(families, "SPEEDS", SPEEDS[:3])
    monkeypatch.setitem(families._SWEEP, "own", (_own_sweep, 0.1))
    truth = draw_trial("thermal-bow", 3, "own")
    bow = truth["effects"]["thermal-bow"]
    assert 2.0 <= bow["relax_steps"] <= 8.0
    relaxing = simulate("own", truth, {"thermal-bow": bow})
    assert list(relaxing.speed.unique()) == list(SPEEDS[:3])
    k = 2  # the step's bow has relaxed to exp(-2 / relax_steps) of the first step's
    now = dict(bow, bow=bow["bow"] * np.exp(-k / bow["relax_steps"]))
    step = _own_sweep(truth, {"thermal-bow": now}, 0.1, speeds=(SPEEDS[k],))
    got = relaxing[relaxing.speed == SPEEDS[k]]
    np.testing.assert_allclose(got[list(CHANNELS)].to_numpy(),
                               step[list(CHANNELS)].to_numpy(), rtol=0, atol=1e-12)
    # a bow not relaxed (the first step's) differs there by more than the noise of a rig
    fixed = _own_sweep(truth, {"thermal-bow": bow}, 0.1, speeds=(SPEEDS[k],))
    assert np.abs(fixed["xO1"].to_numpy() - got["xO1"].to_numpy()).max() > 1e-6


def test_the_families_read_their_speed_steps_at_call_time(monkeypatch):
    # bench_gap_cost.py diagnoses 19-step sweeps by setting plants.families.SPEEDS
    from validation.plants import families

    monkeypatch.setattr(families, "SPEEDS", (100.0, 150.0))
    monkeypatch.setitem(families._SWEEP, "own", (_own_sweep, 0.0))  # short: steps only
    sweep = simulate("own", draw_trial(None, 1, "own"), {})
    assert list(sweep.speed.unique()) == [100.0, 150.0]


def _angle_lag(t, x, w, window=0.2):
    """How far the 1x of a record lags the nominal shaft angle ``w t`` (rad), in sliding
    windows: a speed ripple shows as the wander of this lag."""
    t, x = np.asarray(t), np.asarray(x)
    n = int(round(window / (t[1] - t[0])))
    mids, lag = [], []
    for i in range(0, t.size - n + 1, n // 4):
        v = _orders(t[i:i + n], x[i:i + n], w, 1.0)
        mids.append(t[i:i + n].mean())
        lag.append(np.angle(v))
    return np.array(mids), np.unwrap(lag)


@pytest.mark.parametrize("family", ["own", "second", "ross"])
def test_every_family_ripples_the_speed_as_drawn(family, monkeypatch):
    """The speed ripple's drawn phase (``Omega (1 + a cos(2 pi f t + phase))``, ``t`` each
    record's time) reaches each family's shaft angle: the 1x at a disk wanders by the
    angle's deviation ``a Omega / (2 pi f) (sin(2 pi f t + phase) - sin(phase))`` (up to a
    constant: the response lags the angle by the same amount all through a slow ripple
    far below the critical speed) -- the same law in all three codes."""
    from validation.plants import families

    if family == "ross":
        pytest.importorskip("ross")
    w = 60.0
    monkeypatch.setattr(families, "SPEEDS", (w,))
    truth = draw_trial(None, 4, family)
    ripple = {"amplitude": 0.03, "frequency_hz": 1.5, "phase": 2.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        on = simulate(family, truth, {"speed-fluctuation": ripple})
        off = simulate(family, truth, {})
    t = on.t.to_numpy()
    mid, lag_on = _angle_lag(t, on.xO1.to_numpy(), w)
    _, lag_off = _angle_lag(t, off.xO1.to_numpy(), w)
    wander = lag_on - lag_off
    wf, ph = 2 * np.pi * ripple["frequency_hz"], ripple["phase"]
    law = ripple["amplitude"] * w / wf * (np.sin(wf * mid + ph) - np.sin(ph))
    # the windows average the law over 0.2 s; compare shapes about their means
    a, b = wander - wander.mean(), law - law.mean()
    assert np.corrcoef(a, b)[0, 1] > 0.95
    assert np.std(a) == pytest.approx(np.std(b), rel=0.25)


@pytest.mark.slow
def test_ross_plant_runs_a_settled_sweep_and_its_crack_shows_in_the_two_x():
    pytest.importorskip("ross")
    from validation.plants.families import measure
    from validation.plants.ross_paper_rotor import ross_sweep

    # seed 4: an A-O1 crack of depth 0.34 (seed 3's O2-B crack of depth 0.42 makes the
    # ROSS integration fail at 255 rad/s; the benchmark logs such a trial as skipped).
    # Three of the sweep's speeds (the lowest, the one checked, the highest): the
    # benchmark runs all 19; the format and the crack's 2x are the same per speed
    truth = draw_trial("crack", 4, "ross")
    speeds = [SPEEDS[0], SPEEDS[2], SPEEDS[-1]]
    cracked = ross_sweep(truth, truth["effects"], speeds, CHANNELS)
    free = ross_sweep(truth, {}, speeds, CHANNELS)
    meas = measure(cracked, truth)
    assert list(meas.columns) == ["speed", "t", *CHANNELS]
    assert sorted(meas.speed.unique()) == pytest.approx(speeds)
    assert np.all(np.isfinite(meas[list(CHANNELS)].to_numpy()))
    w = SPEEDS[2]
    o, f = cracked[cracked.speed == w], free[free.speed == w]
    ch = "xO1" if truth["effects"]["crack"]["station"] == "A-O1" else "xB"
    assert abs(_orders(o.t, o[ch], w, 2.0)) > 2 * abs(_orders(f.t, f[ch], w, 2.0))


def test_ross_crack_as_written_drops_the_coupling_the_rotated_form_keeps():
    pytest.importorskip("ross")
    from validation.plants.ross_paper_rotor import PaperRotorROSS, RossPlant

    crack = {"crack": {"station": "A-O1", "depth": 0.45, "angle": 0.0}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        as_written = RossPlant(PaperRotorROSS(faults=crack)).faults["crack"][0]
        rotated = RossPlant(PaperRotorROSS(faults=crack, crack_form="rotated")).faults["crack"][0]
    ix, iy = [0, 4, 6, 10], [1, 3, 7, 9]  # the element's x-plane and y-plane DOFs
    # a vertical deflection of the element (the static sag's shape, 1 mm at its end)
    d = np.zeros(12)
    d[iy] = 1e-3 * np.array([0.0, 0.0, 1.0, 0.0])
    horizontal = {"as-written": [], "rotated": []}
    for ap in np.linspace(0.0, 2 * np.pi, 16, endpoint=False):
        Kw, Kr = as_written.mayes(ap), rotated.mayes(ap)
        np.testing.assert_allclose(Kr, Kr.T, rtol=0, atol=1e-9 * np.abs(Kr).max())
        # the same crack in each plane: only the coupling between them differs
        np.testing.assert_allclose(Kr[np.ix_(ix, ix)], Kw[np.ix_(ix, ix)])
        np.testing.assert_allclose(Kr[np.ix_(iy, iy)], Kw[np.ix_(iy, iy)])
        horizontal["as-written"].append(np.abs((Kw @ d)[ix]).max())
        horizontal["rotated"].append(np.abs((Kr @ d)[ix]).max())
    vertical = np.abs((as_written.mayes(0.0) @ d)[iy]).max()
    # as written, a crack turning in a vertically deflected shaft never pushes sideways
    assert max(horizontal["as-written"]) == 0.0
    # turned with the shaft, it does whenever its axes are oblique: (k_xi - k_eta) sin cos
    assert max(horizontal["rotated"]) > 0.05 * vertical
    assert horizontal["rotated"][0] == pytest.approx(0.0, abs=1e-9 * vertical)
    with pytest.raises(ValueError, match="crack_form"):
        RossPlant(PaperRotorROSS(faults=crack, crack_form="skewed"))


def test_ross_rub_friction_as_written_keeps_one_direction_wherever_the_contact_is():
    """ROSS 2.3's ``Rubbing`` (the ROSS family's rub, docs/upstream_ross.md): its friction
    is ``mu (-|F_x|, +|F_y|)`` of the contact force whatever the contact angle, so where
    the contact is on the x axis it acts along the radius, where a Coulomb friction would
    act along the tangent against the sliding."""
    pytest.importorskip("ross")
    from validation.plants.ross_paper_rotor import PaperRotorROSS, RossPlant

    mu, k, clearance, radius, whirl = 0.15, 3e6, 5e-4, 1e-3, 200.0  # -, N/m, m, m, rad/s

    def rub(friction):
        faults = {"rub": {"at": "O1", "clearance": clearance, "stiffness": k,
                          "friction": friction}}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return RossPlant(PaperRotorROSS(faults=faults)).faults["rub"]

    with_mu, without = rub(mu), rub(0.0)
    normal = k * (radius - clearance)
    for phi in np.linspace(0.0, 2 * np.pi, 16, endpoint=False):
        radial = np.array([np.cos(phi), np.sin(phi)])
        tangent = np.array([-np.sin(phi), np.cos(phi)])
        y, ydot = np.zeros(12), np.zeros(12)
        y[:2], ydot[:2] = radius * radial, radius * whirl * tangent  # forward circular whirl
        contact = without.compute_rubbing_force(y, ydot, whirl)[:2]
        friction = with_mu.compute_rubbing_force(y, ydot, whirl)[:2] - contact
        np.testing.assert_allclose(friction, mu * np.abs(contact) * [-1.0, 1.0], atol=1e-9)
        if np.isclose(np.sin(phi), 0.0, atol=1e-12):
            # on the x axis all of it is along the radius, none along the sliding
            assert abs(friction @ tangent) < 1e-3 * mu * normal
            assert abs(friction @ radial) == pytest.approx(mu * normal, rel=1e-3)


@pytest.mark.slow
def test_update_stays_physical_and_finds_where_the_second_plants_dampers_act():
    from sknarx.gap import SearchBudget
    from sknarx.gap.measured import check_measured
    from sknarx.gap.timeseries import _update_nominal
    from sknarx.orders import order_features
    from sknarx.rotor import RotorParameters

    meas, truth, _, _ = make_family_trial(None, 1, "second")
    m, info = check_measured(meas, None)
    speeds = np.array(info["speeds"])
    feats = order_features(m, info["channels"], 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        upd = _update_nominal(feats, speeds[0::2], info["channels"], RotorParameters(), info,
                              0.0, 2.0, SearchBudget())
    tab = upd.table.set_index("parameter")
    # nothing is dragged beyond three prior widths (with one fixed 1 % tolerance k2
    # moved x18 and c_b x93 on this sweep)
    theta = np.where(tab["log"], np.log1p(tab["change"].astype(float)), tab["change"])
    assert np.all(np.abs(theta) < 3 * tab["prior_std"])
    tol = upd.mismatch["model_tolerance"]
    # this plant's disk dampers act from the disks to the frame: the update says so, and
    # with them there its journals are followed too (measured: shares 1.00 and 0.81;
    # journals' tolerances 0.05-0.12, where with the dampers held across the segments
    # they widened to 0.4-0.9 and the journals stopped counting)
    assert max(tol["xO1"], tol["yO1"]) < 0.05
    assert max(tol[c] for c in ("xA", "yA", "xB", "yB")) < 0.25
    for share in ("frame_share_d1", "frame_share_d2"):
        assert tab.loc[share, "updated"] > 0.5 and tab.loc[share, "significant"]
    assert upd.mismatch["after"] < 0.5 * upd.mismatch["before"]
