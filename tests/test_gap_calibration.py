"""Calibrating a candidate: probes, basins, discrete settings, Jacobians."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sknarx.gap import SearchBudget, VerdictRule, diagnose, order_features
from sknarx.gap.measured import check_measured
from sknarx.testing import make_trial

SPEEDS = tuple(np.linspace(81.7, 276.5, 6).round(4))


def _calibration_setup(measured):
    """What a calibration needs from measured records started from rest: the nominal
    sweep model, the order features and the training speeds (every other step)."""
    from sknarx.gap.sweep_model import SweepModel
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
    # always calibrated (evidence.alternating_split) seed 21 absorbs only 3 %; seed 22
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
    # harmonic tolerance (the rule's harmonic_rtol) the 2x sets the depth less tightly and
    # depth and element stiffness trade: +4.4 % (depth 0.47 for 0.42); seed 22: -2.3 %
    assert abs(fitted / rig - 1) < 0.06


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
    """Every sweep the diagnosis runs uses ``SearchBudget.step_factor``: four RK-4
    steps per 1 kHz sample on the paper rotor at 2.5, against the simulator's five."""
    from sknarx.gap.sweep_model import SweepModel
    from sknarx.rotor import RotorParameters

    nuis = np.array([1.0, 0.0, 1.0, 1.0])
    steps = {}
    for factor in (2.0, SearchBudget().step_factor):
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
    from types import SimpleNamespace

    from sknarx._checkpoint import NoCheckpoint
    from sknarx.gap import sweep_front as dg
    from sknarx.gap.calibration import calibrate
    from sknarx.rotor import EFFECTS

    def probes(name):  # the partner's probes and its start
        return 2 ** math.ceil(math.log2(8 * len(EFFECTS[name].bounds))) + 1

    assert probes("clearance") == probes("looseness") == 16 + 1
    measured, _ = make_trial("clearance", 2, speeds=SPEEDS[:4], n_samples=400)
    model, meas, train, _ = _calibration_setup(measured)
    cal0 = calibrate(model, meas, train, (), max_nfev=2)
    lead_cal = calibrate(model, meas, train, [EFFECTS["runout"]], starts=[cal0.x],
                         max_nfev=0)
    lead = SimpleNamespace(effects=("runout",), state=lead_cal)
    budget = SearchBudget(pair_probes_per_parameter=8, pair_short_starts=2)
    front = dg.SweepFrontEnd(model, meas, train, train, None, VerdictRule(), budget, cal0.x,
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
    monkeypatch.setattr(dg, "heldout_gap", lambda *a, **k: (1.0, None))
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

    import sknarx.gap.timeseries as D

    seen = []
    monkeypatch.setattr(D._Run, "__init__", lambda *a: seen.append(
        [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]))
    monkeypatch.setattr(D._Run, "diagnose", lambda self: None)
    with threadpool_limits(limits=2, user_api="blas"):
        D.diagnose(None)
    assert seen and seen[0] and all(n == 1 for n in seen[0])
