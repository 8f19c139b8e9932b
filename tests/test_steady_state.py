"""The harmonic balance against the integrator, its convergence, and its fallbacks."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sknarx.rotor as R
from sknarx.gap import SearchBudget
from sknarx.gap.sweep_model import SweepModel
from sknarx.orders import record_features
from sknarx.rotor import _hb_kernels as hbk
from sknarx.rotor.steady import (
    N_CAGE,
    HarmonicBalanceError,
    solve_steady_state,
    steady_columns,
    supports_harmonic_balance,
)

CHANNELS = ["xO1", "yO1", "xA", "yA", "xB", "yB"]
SPEEDS = (81.7, 180.0, 276.5)

#: every effect of the library whose settled response is locked to the shaft
PERIODIC = {
    "none": [],
    "crack A-O1": [R.BreathingCrack(station="A-O1", depth=0.4)],
    "crack joint": [R.BreathingCrack(station="joint", depth=0.4)],
    "misalignment": [R.Misalignment()],
    "anisotropy": [R.SupportAnisotropy()],
    "support-flexibility": [R.SupportFlexibility()],
    "runout": [R.ProbeRunout(vectors={"xO1": (2e-6 + 1e-6j, 5e-7)})],
}


def _orders(record, w):
    keys, vals, _, _ = record_features(
        (w, record["t"], np.column_stack([record[c] for c in CHANNELS])), CHANNELS, 0.5)
    return {(k[2], k[3]): v for k, v in zip(keys, vals, strict=True)
            if k[1] == "steady" and k[3] in ("1x", "2x", "3x")}


@pytest.mark.parametrize("name", list(PERIODIC))
def test_the_balance_gives_the_integrators_orders(name):
    """Order by order, each channel's 1x, 2x and 3x of a balanced record agree with
    those of a record integrated through 3 s of settling to 1 % of that channel's 1x
    (the gap comparison's own relative tolerance) on every periodic effect."""
    sim = R.RotorBearingSimulator(effects=PERIODIC[name])
    assert supports_harmonic_balance(sim)
    for w in SPEEDS:
        integrated = _orders(sim.simulate_columns(w, fs=1000.0, n_samples=1000,
                                                  settle=3.0), w)
        balanced = _orders(steady_columns(sim, solve_steady_state(sim, w), 1000.0, 1000), w)
        for ch in CHANNELS:
            scale = abs(integrated[(ch, "1x")])
            for order in ("1x", "2x", "3x"):
                err = abs(balanced[(ch, order)] - integrated[(ch, order)])
                assert err <= 0.01 * scale, (name, w, ch, order, err, scale)


def test_without_the_ball_passage_lines_the_low_speed_1x_is_off():
    """The first-order ball-pass lines matter: at 81.7 rad/s their 1.08x sideband leaks
    into the 1x fit of a one-second record; without them a bearing's 1x is off by
    more than with them (the balanced orbit alone is the cage-averaged one)."""
    sim = R.RotorBearingSimulator()
    w = 81.7
    integrated = _orders(sim.simulate_columns(w, fs=1000.0, n_samples=1000, settle=3.0), w)
    errors = []
    for ball_pass in (True, False):
        state = solve_steady_state(sim, w, ball_pass=ball_pass)
        got = _orders(steady_columns(sim, state, 1000.0, 1000), w)
        errors.append(max(abs(got[(c, "1x")] - integrated[(c, "1x")]) for c in CHANNELS))
    assert errors[0] < 0.3 * errors[1]


def test_more_harmonics_change_the_read_orders_little():
    """Eight harmonics hold a switching crack's harmonics well enough: twenty-four move
    no order up to 3x by more than 0.2 % of the largest 1x (a fifth of the comparison's
    1 %; six harmonics leave 0.4 % at 276.5 rad/s)."""
    sim = R.RotorBearingSimulator(effects=[R.BreathingCrack(depth=0.5)])
    for w in SPEEDS:
        a = solve_steady_state(sim, w)
        b = solve_steady_state(sim, w, harmonics=16)
        big = np.max(np.abs(a.order_vector(1)))
        for k in (1, 2, 3):
            assert np.max(np.abs(a.order_vector(k) - b.order_vector(k))) < 2e-3 * big


def test_eight_cage_positions_average_the_bearing():
    """The bearings are averaged over ``N_CAGE`` cage positions: at the static load the
    mean force is within 1e-4 of a 64-position mean."""
    sim = R.RotorBearingSimulator()
    q = sim.static_equilibrium()
    p = sim.params
    pitch = hbk.ball_pitch(p.n_balls)
    out = {}
    for n_cage in (N_CAGE, 64):
        f = np.empty(6)
        hbk._bearing_mean(q[0], q[1], p.kB, p.clearance, p.hertz_exponent, p.n_balls,
                          n_cage, pitch[0], pitch[1], f)
        out[n_cage] = f[:2].copy()
    assert np.max(np.abs(out[N_CAGE] - out[64])) < 1e-4 * np.max(np.abs(out[64]))


@settings(max_examples=15, deadline=None)
@given(k_scale=st.floats(0.9, 1.1), c_scale=st.floats(0.7, 1.4),
       w=st.floats(80.0, 280.0))
def test_the_solution_does_not_depend_on_the_start(k_scale, c_scale, w):
    """From rest on the static deflection or from a nearby rotor's solution (chord
    steps with its Jacobian), the balance reaches the same orbit."""
    start_sim = R.RotorBearingSimulator(effects=[R.BreathingCrack(depth=0.3)])
    start = solve_steady_state(start_sim, w, keep_jacobian=True)
    p = start_sim.params
    sim = R.RotorBearingSimulator(p.replace(k1=p.k1 * k_scale, c_a=p.c_a * c_scale),
                                  effects=[R.BreathingCrack(depth=0.3)])
    cold = solve_steady_state(sim, w)
    warm = solve_steady_state(sim, w, start=start)
    scale = np.max(np.abs(cold.coefficients))
    assert np.max(np.abs(cold.coefficients - warm.coefficients)) < 1e-7 * scale


def test_a_balance_that_cannot_converge_says_so():
    sim = R.RotorBearingSimulator()
    with pytest.raises(HarmonicBalanceError, match="did not converge"):
        solve_steady_state(sim, 150.0, max_iter=1)
    with pytest.raises(ValueError, match="positive speed"):
        solve_steady_state(sim, 0.0)


@pytest.mark.parametrize("effect", [R.ClearanceChange(), R.SpeedFluctuation()])
def test_effects_that_can_leave_the_shaft_periodic_orbit_are_integrated(effect):
    assert not supports_harmonic_balance(R.RotorBearingSimulator(effects=[effect]))


@pytest.mark.parametrize("effect, idle", [
    (R.Rub(clearance=2e-3), True), (R.Rub(clearance=1e-4), False),
    (R.JointLooseness(gap=1e-3), True), (R.JointLooseness(gap=1e-7), False)])
def test_a_contact_is_balanced_only_where_it_stays_open(effect, idle):
    """A rub or a loose joint acts through a force alone: where that force is nil along
    the balanced orbit (enlarged by the margin) the orbit is the rotor's without it;
    where it acts, the orbit may be sub-synchronous and the balance declines."""
    sim = R.RotorBearingSimulator(effects=[effect])
    assert supports_harmonic_balance(sim)
    if idle:
        got = solve_steady_state(sim, 200.0)
        bare = solve_steady_state(R.RotorBearingSimulator(), 200.0)
        assert np.array_equal(got.coefficients, bare.coefficients)
    else:
        with pytest.raises(HarmonicBalanceError, match="acts on|stalled|did not converge"):
            solve_steady_state(sim, 200.0)


def test_a_users_effect_is_integrated_unless_it_keeps_the_package_kernels():
    class Ripple(R.Effect):
        name = "ripple"

        def modify_speed(self, t, omega, rng):
            return omega * (1.0 + 0.01 * np.sin(t))

    assert not supports_harmonic_balance(R.RotorBearingSimulator(effects=[Ripple()]))
    assert supports_harmonic_balance(R.RotorBearingSimulator(effects=[R.Effect()]))


def _model(solver, settle=2.0):
    return SweepModel(base=R.RotorParameters(), fs=1000.0, n_samples=600,
                      channels=tuple(CHANNELS), settle_s=settle, solver=solver)


def test_the_sweep_model_balances_settled_records_and_integrates_the_rest(monkeypatch):
    nuis = np.array([1.0, 0.0, 1.0, 1.0])
    speeds = [120.0, 200.0]
    calls = []
    import sknarx.gap.sweep_model as sm

    real = sm.solve_steady_state
    monkeypatch.setattr(sm, "solve_steady_state",
                        lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    balanced = _model("harmonic-balance").features(speeds, nuis)
    assert sorted(calls) == speeds
    integrated = _model("integrate").features(speeds, nuis)
    assert len(calls) == 2
    one = (balanced.feature == "1x") & (balanced.window == "steady")
    diff = np.hypot(balanced.re - integrated.re, balanced.im - integrated.im)[one]
    amp = np.hypot(integrated.re, integrated.im)[one]
    assert np.all(diff <= 0.01 * amp)
    # a speed ripple is integrated, and so is a record from rest (its transient is
    # the point)
    _model("harmonic-balance").features(speeds, nuis, [R.SpeedFluctuation()])
    _model("harmonic-balance", settle=0.0).features(speeds, nuis)
    assert len(calls) == 2


def test_a_failed_balance_falls_back_to_the_integrator(monkeypatch):
    import sknarx.gap.sweep_model as sm

    def fail(*args, **kwargs):
        raise HarmonicBalanceError("stalled")

    monkeypatch.setattr(sm, "solve_steady_state", fail)
    nuis = np.array([1.0, 0.0, 1.0, 1.0])
    got = _model("harmonic-balance").features([150.0], nuis)
    want = _model("integrate").features([150.0], nuis)
    assert np.array_equal(got.re.to_numpy(), want.re.to_numpy())


def test_balanced_features_are_reproducible_whatever_the_start():
    """A warmed model's evaluations start from its start point's solutions, not from
    whichever evaluation a thread ran last: the same point gives the same bits."""
    model = _model("harmonic-balance")
    nuis = np.array([1.0, 0.0, 1.0, 1.0])
    speeds = [100.0, 150.0, 250.0]
    warm = model.warmed(speeds, nuis)
    first = warm.features(speeds, nuis * np.array([1.01, 1, 1, 1]))
    warm.features(speeds, nuis * np.array([0.9, 1, 1.05, 1]))
    again = warm.features(speeds, nuis * np.array([1.01, 1, 1, 1]))
    assert np.array_equal(first.re.to_numpy(), again.re.to_numpy())


def test_the_budget_names_the_solver():
    assert SearchBudget().solver == "integrate"
    assert SearchBudget(solver="harmonic-balance").solver == "harmonic-balance"
    with pytest.raises(ValueError, match="solver"):
        SearchBudget(solver="shooting")


def test_a_rub_the_orbit_nearly_reaches_is_not_balanced():
    """``IDLE_MARGIN``: a stator 2 % beyond the orbit's largest excursion is too close
    to call the contact idle (the ball passage and a record's residual decay move the
    orbit); 10 % beyond it is idle."""
    w = 200.0
    bare = R.RotorBearingSimulator()
    state = solve_steady_state(bare, w)
    i, j = state.dof_names.index("xO1"), state.dof_names.index("yO1")
    t = np.linspace(0.0, 2 * np.pi / w, 2000)
    q = state.displacements(t)
    q0 = bare.static_equilibrium()
    reach = np.max(np.hypot(q[:, i] - q0[i], q[:, j] - q0[j]))
    near = R.RotorBearingSimulator(effects=[R.Rub(clearance=1.02 * reach)])
    with pytest.raises(HarmonicBalanceError, match="acts on"):
        solve_steady_state(near, w)
    far = R.RotorBearingSimulator(effects=[R.Rub(clearance=1.10 * reach)])
    assert np.array_equal(solve_steady_state(far, w).coefficients, state.coefficients)
