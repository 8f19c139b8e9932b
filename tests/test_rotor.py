import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sknarx.rotor as R
from sknarx.orders import order_components
from sknarx.rotor.linear import bearing_stiffness
from sknarx.rotor.matrices import assemble
from sknarx.rotor.reference import solve_reference

PAPER_PEAK = 144.5  # rad/s, paper Fig. 2


@pytest.fixture(scope="module")
def sim():
    return R.RotorBearingSimulator()


@pytest.fixture(scope="module")
def coarse_sweep(sim):
    speeds = np.arange(50.0, 320.0 + 1e-9, 2.0)
    return sim.sweep(speeds, fs=1000.0, n_samples=1000, settle=1.0, n_jobs=2, progress=False)


def test_parameters_defaults_and_validation():
    p = R.RotorParameters()
    assert p.kB == 13.34e9 and p.n_balls == 8 and p.span == pytest.approx(0.9)
    assert p.ball_pass_ratio == pytest.approx(3.08, abs=0.01)  # paper's BN
    with pytest.raises(ValueError, match="m_O1"):
        R.RotorParameters(m_O1=-1.0)
    with pytest.raises(ValueError, match="k1"):
        R.RotorParameters(k1=float("nan"))
    with pytest.raises(ValueError, match="swap J_polar"):
        R.RotorParameters(J_polar1=0.5)
    with pytest.raises(ValueError, match="span"):
        R.RotorParameters(b2=0.7)
    assert R.RotorParameters.from_dict(p.to_dict()) == p


def test_matrices_structure_and_rigid_body_invariance():
    m = assemble(R.RotorParameters())
    np.testing.assert_allclose(m.K, m.K.T)
    np.testing.assert_allclose(m.C, m.C.T)
    np.testing.assert_allclose(m.G, -m.G.T)
    lam = np.linalg.eigvalsh(m.K)
    assert lam.min() > -1e-6 * lam.max()
    # free rotor (no bearings): 2 translations + 2 rigid rotations store no energy
    assert np.sum(lam < 1e-9 * lam.max()) == 4
    rigid = np.zeros(12)
    for name, z in (("xA", 0.0), ("xO1", 0.29), ("xO2", 0.31), ("xB", 0.9)):
        rigid[R.DOF_NAMES.index(name)] = 1e-3 + 2e-3 * z  # translation + rotation
    rigid[R.DOF_NAMES.index("tyO1")] = rigid[R.DOF_NAMES.index("tyO2")] = 2e-3
    np.testing.assert_allclose(m.K @ rigid, 0.0, atol=1e-9 * np.abs(m.K).max() * 1e-3)


def test_gyroscopic_stiffening_of_forward_modes(sim):
    lin = sim.linear_model()
    camp = lin.campbell([0.0, 300.0, 600.0], n_modes=6)
    fwd = camp[(camp.whirl == "forward") & (camp.frequency > 500)].groupby("speed").frequency.min()
    assert fwd.loc[600.0] > fwd.loc[300.0]
    crit = lin.critical_speeds(1000.0)
    assert 100 < crit[0] < 160


@pytest.mark.xdist_group("coarse-sweep")  # one core builds the sweep
def test_peak_of_disk_amplitude_matches_paper(coarse_sweep):
    amp = coarse_sweep.groupby("speed")["xO1"].agg(lambda x: (x.max() - x.min()) / 2)
    peak = amp.idxmax()
    assert abs(peak - PAPER_PEAK) / PAPER_PEAK < 0.03, peak


def test_second_harmonic_from_gravity_preloaded_bearings(sim):
    run = sim.simulate(250.0, fs=1000.0, n_samples=4096, settle=1.0)
    amp = {d: order_components(run[d], run["phi"], (1, 2))[0] for d in ("xO1", "xA")}
    # 2x is present at the disk and strongest (relative to 1x) at the bearing journal
    assert amp["xO1"][1] > 1e-4 * amp["xO1"][0]
    assert amp["xA"][1] / amp["xA"][0] > amp["xO1"][1] / amp["xO1"][0]
    no_g = R.RotorBearingSimulator(R.RotorParameters(gravity=0.0)).simulate(
        250.0, fs=1000.0, n_samples=4096, settle=1.0)
    a0 = order_components(no_g["xO1"], no_g["phi"], (1, 2))[0]
    assert a0[1] < 0.05 * amp["xO1"][1]


def _assert_matches_reference(sim, w, t_end, skip, dofs, fs=1000.0):
    """The RK-4 run's 1x and 2x at ``dofs`` equal a tight SciPy reference's (rtol 1e-4)
    once the first ``skip`` samples are past."""
    ref, _ = solve_reference(sim, w, t_end, fs, rtol=1e-10)
    run = sim.simulate(w, fs=fs, n_samples=ref.shape[0], settle=0.0)
    window = slice(skip, None)
    phi = run["phi"].to_numpy()[window]
    for dof in dofs:
        i = R.DOF_NAMES.index(dof)
        a_ref = order_components(ref[window, i], phi, (1, 2))[0]
        a = order_components(run[dof].to_numpy()[window], phi, (1, 2))[0]
        np.testing.assert_allclose(a, a_ref, rtol=1e-4)


def test_integrator_accuracy_against_tight_reference(sim):
    _assert_matches_reference(sim, 250.0, 0.6, 300, ("xO1", "yO1", "xA"))


def test_identical_for_any_n_jobs_and_repeated_runs(sim):
    speeds = [90.0, 150.0, 210.0]
    a = sim.sweep(speeds, fs=500.0, n_samples=300, settle=0.5, n_jobs=1, progress=False)
    b = sim.sweep(speeds, fs=500.0, n_samples=300, settle=0.5, n_jobs=2, progress=False)
    c = sim.sweep(speeds, fs=500.0, n_samples=300, settle=0.5, n_jobs=2, progress=False)
    pd.testing.assert_frame_equal(a, b)
    pd.testing.assert_frame_equal(b, c)


@pytest.mark.xdist_group("coarse-sweep")  # one core builds the sweep
def test_sweep_table_layout(coarse_sweep):
    cols = list(coarse_sweep.columns)
    assert cols[:4] == ["speed", "t", "u", "phi"] and cols[4:] == list(R.DOF_NAMES)
    first = coarse_sweep[coarse_sweep.speed == 100.0]
    assert first.t.iloc[0] == 0.0 and first.phi.iloc[0] == pytest.approx(0.0, abs=1e-9)
    p = R.RotorParameters()
    np.testing.assert_allclose(first.u, p.m_O1 * p.e * 100.0**2 * np.cos(100.0 * first.t),
                               rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_bad_speeds_rejected(sim, bad):
    with pytest.raises(ValueError, match="finite and non-negative"):
        sim.sweep([100.0, bad], fs=500.0, n_samples=10, settle=0.0, progress=False)


def test_bad_grid_rejected(sim):
    with pytest.raises(ValueError, match="fs"):
        sim.simulate(100.0, fs=0.0)
    with pytest.raises(ValueError, match="n_samples"):
        sim.simulate(100.0, n_samples=0)
    with pytest.raises(ValueError, match="settle"):
        sim.simulate(100.0, settle=-1.0)


def test_unstable_step_is_detected_and_explained(sim):
    with pytest.raises(R.SimulationDivergenceError, match="smaller integration step"):
        sim.simulate(150.0, fs=200.0, n_samples=200, settle=0.0, substeps=1)


def test_sweep_resumes_after_interruption(sim, tmp_path, monkeypatch):
    speeds = [100.0, 140.0, 180.0]
    kw = dict(fs=500.0, n_samples=200, settle=0.2, progress=False)
    sim.sweep(speeds[:2], path=tmp_path / "sw", **kw)  # "interrupted" after two speeds
    calls = []
    original = R.RotorBearingSimulator.simulate

    def counting(self, w, **k):
        calls.append(w)
        return original(self, w, **k)

    monkeypatch.setattr(R.RotorBearingSimulator, "simulate", counting)
    full = sim.sweep(speeds, path=tmp_path / "sw", **kw)
    assert calls == [180.0]
    fresh = R.RotorBearingSimulator().sweep(speeds, **kw)
    pd.testing.assert_frame_equal(full.reset_index(drop=True), fresh, check_dtype=False)
    assert R.load_sweep(tmp_path / "sw").attrs["settings"]["fs"] == 500.0
    other = R.RotorBearingSimulator(R.RotorParameters(k1=9e5))
    with pytest.raises(ValueError, match="different settings"):
        other.sweep(speeds, path=tmp_path / "sw", **kw)


@pytest.mark.parametrize("suffix", [".parquet", ".csv"])
def test_save_and_load_with_settings(sim, tmp_path, suffix):
    if suffix == ".parquet":
        pytest.importorskip("pyarrow")
    df = sim.sweep([120.0], fs=500.0, n_samples=50, settle=0.1, progress=False)
    R.save_sweep(df, tmp_path / ("s" + suffix))
    back = R.load_sweep(tmp_path / ("s" + suffix))
    pd.testing.assert_frame_equal(back, df)
    assert back.attrs["settings"]["params"]["kB"] == 13.34e9


def test_run_up_includes_angular_acceleration(sim):
    fs = 1000.0
    run = sim.run_up(lambda t: 100.0 + 50.0 * t, fs=fs, duration=1.0, settle=0.5)
    assert run.speed.iloc[0] == pytest.approx(100.0) and run.speed.iloc[-1] > 149.0
    p = R.RotorParameters()
    w, phi = run.speed.to_numpy(), run.phi.to_numpy()
    expected = p.m_O1 * p.e * (w**2 * np.cos(phi) + 50.0 * np.sin(phi))
    np.testing.assert_allclose(run.u, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(phi[-1], 100.0 * 0.999 + 25.0 * 0.999**2, rtol=1e-9)
    # a constant profile equals a steady run
    steady = sim.run_up(np.full(300, 120.0), fs=fs, settle=0.5)
    ref = sim.simulate(120.0, fs=fs, n_samples=300, settle=0.5)
    np.testing.assert_allclose(steady["xO1"], ref["xO1"], rtol=1e-12, atol=1e-15)


def test_effects_compose_without_touching_the_integrator():
    base = R.RotorBearingSimulator()
    # partial rub: the 1.06 mm orbit at the peak touches a 0.8 mm clearance
    rub = R.RotorBearingSimulator(effects=[R.Rub(clearance=8e-4, stiffness=2e7, friction=0.1)])
    both = R.RotorBearingSimulator(effects=[
        R.Rub(clearance=8e-4, stiffness=2e7, friction=0.1),
        R.Rub(clearance=8e-4, stiffness=2e7, friction=0.1, at="O2"),
    ])
    kw = dict(fs=1000.0, n_samples=2048, settle=1.0)
    a = base.simulate(144.5, **kw)
    b = rub.simulate(144.5, **kw)
    c = both.simulate(144.5, **kw)
    amp = lambda r, d="xO1": order_components(r[d], r["phi"], (1, 2, 3))[0]  # noqa: E731
    assert amp(b)[0] < 0.9 * amp(a)[0]  # contact limits the 1x amplitude at the peak
    assert amp(b)[1] > 2 * amp(a)[1] and amp(b)[2] > 2 * amp(a)[2]  # and creates 2x, 3x
    assert amp(c, "xO2")[0] < amp(b, "xO2")[0]


def test_every_combination_of_built_in_effects_runs_one_compiled_integrator():
    # numba compiles the integrator anew for each kernel it is handed (about 5 s a
    # time): the package's own kernels go in as one program of one dispatcher, so a
    # search over effects and pairs compiles it once; a user's kernel is chained after
    from sknarx.rotor.effects import builtin_forces, compose_force_kernels
    from sknarx.rotor.integrator import _integrate_builtin, _rk4
    from sknarx.testing import ThermalBow

    kw = dict(fs=1000.0, n_samples=200, settle=0.1)
    effects = [R.BreathingCrack(depth=0.3), R.Rub(clearance=2e-4),
               R.Misalignment(parallel=2e-4), R.JointLooseness(residual=0.01, gap=1e-6)]
    R.RotorBearingSimulator(effects=effects[:1]).simulate_columns(150.0, **kw)
    compiled = len(_integrate_builtin.signatures), len(_rk4.signatures)
    assert compiled[0] == 1
    for combo in ([], effects[1:2], effects[2:4], effects):
        sim = R.RotorBearingSimulator(effects=combo)
        assert sim._setup.kernel is builtin_forces
        sim.simulate_columns(150.0, **kw)
    assert (len(_integrate_builtin.signatures), len(_rk4.signatures)) == compiled

    # the program adds what each kernel adds on its own; a user's kernel is added too
    ctx = R.RotorBearingSimulator()._setup.context
    q, v = np.linspace(-1e-4, 1e-4, 12), np.linspace(1e-3, -1e-3, 12)
    bow = ThermalBow(bow=1e-4, angle=0.3)
    parts = [e.force_kernel(ctx) for e in [*effects, bow]]

    def forces(kernel, p):
        out = np.zeros(12)
        kernel(0.01, 0.7, 150.0, 0.0, q, v, p, out)
        return out

    alone = sum(forces(k, np.asarray(p, dtype=float)) for k, p in parts)
    assert np.any(alone != 0.0)
    np.testing.assert_allclose(forces(*compose_force_kernels(parts)), alone,
                               rtol=1e-12, atol=1e-12 * np.max(np.abs(alone)))


def test_a_new_process_loads_the_built_in_integrator_from_numbas_cache(tmp_path):
    # the RK-4 loop with the package's own forces is cached on disk: a process that
    # simulates does not compile it again (it once cost every test worker, CLI start and
    # benchmark process 10-30 s); a hook passed by value would forbid the cache
    import subprocess
    import sys

    script = (
        "import sknarx.rotor as R\n"
        "from sknarx.rotor.integrator import _integrate_builtin as f\n"
        "R.RotorBearingSimulator(effects=[R.Rub(clearance=2e-4)]).simulate_columns("
        "150.0, fs=1000.0, n_samples=50, settle=0.05)\n"
        "print(sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()))\n"
    )
    runs = [subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                           check=True, cwd=tmp_path).stdout.split()[-2:] for _ in range(2)]
    # the first may compile (a cold cache) and save; the second must load
    assert runs[1] == ["1", "0"], runs


def test_measurement_effects_runout_and_noise():
    kw = dict(fs=1000.0, n_samples=2000, settle=1.0)
    clean = R.RotorBearingSimulator().simulate(100.0, **kw)
    ro = R.RotorBearingSimulator(effects=[R.ProbeRunout(amplitude=1e-5, phase=0.3)]).simulate(
        100.0, **kw)
    d = ro["xO1"] - clean["xO1"]
    np.testing.assert_allclose(d, 1e-5 * np.cos(clean["phi"] + 0.3), atol=1e-15)
    noisy = R.RotorBearingSimulator(effects=[R.MeasurementNoise(snr_db=20.0)], seed=3)
    n1 = noisy.simulate(100.0, **kw)
    resid = n1["xO1"] - clean["xO1"]
    snr = 10 * np.log10(np.var(clean["xO1"]) / np.var(resid))
    assert 19.0 < snr < 21.0
    pd.testing.assert_frame_equal(n1, noisy.simulate(100.0, **kw))  # seeded


def test_simulate_columns_records_what_a_probe_would_at_the_nominal_speed():
    # the calibration's inner loop runs on these arrays (simulate wraps them in a table)
    effects = [R.MeasurementNoise(snr_db=25.0), R.ProbeRunout(amplitude=1e-5, phase=0.3),
               R.SpeedFluctuation(amplitude=0.01, frequency=3.0)]
    sim = R.RotorBearingSimulator(effects=effects, seed=5)
    kw = dict(fs=1000.0, n_samples=700, settle=0.3)
    cols = sim.simulate_columns(120.0, **kw)
    assert list(cols) == ["speed", "t", "u", "phi", *R.DOF_NAMES]
    assert all(v.shape == (700,) for v in cols.values())  # settling and the extra sample cut
    assert np.all(cols["speed"] == 120.0)  # the nominal speed, not the fluctuating one
    np.testing.assert_allclose(cols["t"], np.arange(700) / 1000.0, rtol=0, atol=1e-15)
    # the shaft angle follows the fluctuating speed, so it is not omega * t
    assert np.max(np.abs(cols["phi"] - 120.0 * cols["t"])) > 1e-3
    again = sim.simulate_columns(120.0, **kw)  # seeded noise: repeatable, not aliased
    again["xO1"] = again["xO1"] + 1.0
    np.testing.assert_array_equal(sim.simulate_columns(120.0, **kw)["xO1"], cols["xO1"])


@settings(max_examples=8, deadline=None)
@given(lead=st.floats(0.0, 0.4), omega=st.floats(60.0, 300.0))
def test_a_run_continued_from_its_warm_state_repeats_the_long_run(lead, omega):
    # the calibration's local searches continue settled runs (warm_state): with the
    # same parameters, effects and speed modulation the continued record is the long
    # run's record, whatever the lead
    effects = [R.BreathingCrack(depth=0.2, angle=0.4),
               R.SpeedFluctuation(amplitude=0.01, frequency=3.0)]
    sim = R.RotorBearingSimulator(effects=effects, seed=2)
    long = sim.simulate_columns(omega, n_samples=300, settle=0.4)
    state = sim.warm_state(omega, settle=0.4, lead=lead)
    short = sim.simulate_columns(omega, n_samples=300, settle=lead, state=state)
    for name in ("xO1", "yB", "phi"):
        scale = np.max(np.abs(long[name]))
        np.testing.assert_allclose(short[name], long[name], rtol=0, atol=1e-9 * scale)


def test_warm_state_input_is_checked(sim):
    with pytest.raises(ValueError, match="lead must lie in"):
        sim.warm_state(100.0, settle=0.2, lead=0.5)
    with pytest.raises(ValueError, match="settle"):
        sim.warm_state(100.0, settle=-1.0)


def _small_beam(kx=1e5, ky=1e5):
    from sknarx.rotor.beam import BeamRotor, Bearing, Disk

    return BeamRotor(0.5, 0.01, n_elements=10, disks=(Disk(0.25, 0.8, 0.076, 0.025),),
                     bearings=(Bearing(0.0, kx, ky, 60.0, 60.0), Bearing(0.5, kx, ky, 60.0, 60.0)))


def test_a_slow_run_up_tracks_the_steady_response():
    from sknarx.rotor.runup import runup_order_response, sweep_parameter

    rotor = _small_beam().with_bearings(cxx=600.0, cyy=600.0)
    assert sweep_parameter(rotor, 2.0)["sweep_parameter"] < 0.01  # quasi-steady
    rpm, Z = runup_order_response(rotor, 1200.0, 2300.0, 2.0, probe=0.25, n_modes=24,
                                  samples_per_rev=64)
    ss = rotor.probe_responses(rpm * 2 * np.pi / 60, 0.25)[:, 0, 0]
    assert np.max(np.abs(Z[:, 0, 0, 0] - ss)) < 0.01 * np.max(np.abs(ss))
    # isotropic: a unit unbalance 90 degrees ahead gives i times the tracked vector
    assert np.max(np.abs(Z[:, 0, 1, 0] - 1j * Z[:, 0, 0, 0])) < 0.002 * np.max(np.abs(ss))


def test_a_fast_run_up_lowers_and_delays_the_peak_and_leaves_a_beat():
    from sknarx.rotor.runup import runup_order_response, sweep_parameter

    rotor = _small_beam()
    fast = sweep_parameter(rotor, 300.0)["sweep_parameter"]
    assert fast > 10 * sweep_parameter(rotor, 3.0)["sweep_parameter"]
    rpm_s, Zs = runup_order_response(rotor, 1200.0, 2300.0, 3.0, probe=0.25, n_modes=8)
    rpm_f, Zf = runup_order_response(rotor, 1200.0, 2300.0, 300.0, probe=0.25, n_modes=8)
    a_s, a_f = np.abs(Zs[:, 0, 0, 0]), np.abs(Zf[:, 0, 0, 0])
    assert a_f.max() < 0.9 * a_s.max()
    assert rpm_f[np.argmax(a_f)] > rpm_s[np.argmax(a_s)] + 20
    after = a_f[rpm_f > rpm_f[np.argmax(a_f)]]
    assert np.sum(np.diff(np.sign(np.diff(after))) > 0) >= 2  # minima of the beat


def test_run_up_input_is_checked():
    from sknarx.rotor.runup import runup_order_response

    with pytest.raises(ValueError, match="rpm_start < rpm_end"):
        runup_order_response(_small_beam(), 3000.0, 600.0, 100.0, probe=0.25)
    with pytest.raises(ValueError, match="rate_rpm_s"):
        runup_order_response(_small_beam(), 600.0, 3000.0, 0.0, probe=0.25)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(kx=st.floats(1e6, 1e9), ky=st.floats(1e6, 1e9), mass=st.floats(2.0, 40.0),
       damping=st.floats(0.0, 2e4), omega=st.floats(10.0, 400.0))
def test_pedestals_condense_to_the_series_support(kx, ky, mass, damping, omega):
    """The linearised rotor on pedestals (16 DOF), condensed at the running speed, is
    the 12-DOF rotor whose bearings are each in series with a pedestal: bearing
    ``z = K_b + i w c_a`` (the contact's tangent stiffness and the damper, journal to
    housing) and pedestal ``s = diag(k_p) - m w^2 + i w c`` give ``z - z (z + s)^-1 z``.
    Checks the housings' mass, the pedestals, the damper moved off the frame and the
    contact between journal and housing, against an independent algebraic form."""
    p = R.RotorParameters()
    nominal = R.RotorBearingSimulator(p).linear_model()
    eff = R.SupportAnisotropy(kx=kx, ky=ky, mass=mass, damping=damping)
    lin = R.RotorBearingSimulator(p, effects=[eff]).linear_model()
    w = omega
    X16 = np.linalg.solve(lin.K - w * w * lin.M + 1j * w * (lin.C + w * lin.G),
                          w * w * lin.unbalance)
    D = nominal.K - w * w * nominal.M + 1j * w * (nominal.C + w * nominal.G)
    s = np.diag([kx - mass * w * w + 1j * w * damping, ky - mass * w * w + 1j * w * damping])
    q0 = R.RotorBearingSimulator(p).static_equilibrium()
    for j, ca, which in (([0, 1], p.c_a, "A"), ([10, 11], p.c_b, "B")):
        # the journal block holds the bearing z (against the frame); series: z - D_s
        z = bearing_stiffness(*q0[j], p, which=which) + 1j * w * ca * np.eye(2)
        D[np.ix_(j, j)] -= z @ np.linalg.solve(z + s, z)
    X12 = np.linalg.solve(D, w * w * nominal.unbalance)
    np.testing.assert_allclose(X16[:12], X12, rtol=1e-7, atol=1e-12 * np.abs(X12).max())


def test_the_housings_carry_the_weight_and_the_contact_its_share():
    """Statics on pedestals: the pedestals carry the rotor's and the housings' weight,
    and each journal sits in its housing as it sits in the frame without pedestals (a
    rotor on two bearings is statically determinate: the bearing loads do not change)."""
    p = R.RotorParameters()
    eff = R.SupportAnisotropy(kx=3e6, ky=8e6, mass=12.0)
    sim = R.RotorBearingSimulator(p, effects=[eff])
    q = sim.static_equilibrium()
    assert sim.dof_names[12:] == R.HOUSING_NAMES and q.size == 16
    weight = (p.m_A + p.m_B + p.m_O1 + p.m_O2 + 2 * eff.mass) * p.gravity
    assert -eff.ky * (q[13] + q[15]) == pytest.approx(weight, rel=1e-9)
    assert q[12] == pytest.approx(0.0, abs=1e-15) and q[14] == pytest.approx(0.0, abs=1e-15)
    bare = R.RotorBearingSimulator(p).static_equilibrium()
    np.testing.assert_allclose([q[1] - q[13], q[11] - q[15]], bare[[1, 11]], rtol=1e-7)


def test_a_soft_pedestal_lets_the_journal_move_more():
    """Simulated 1x at the journals: a soft pedestal under the contact lets them move
    more (on the paper rotor the shaft segments, 0.8 MN/m, are far softer than the
    contacts, ~1e8 N/m: the disks barely notice; the journals do); probes in the
    housings move with them and read a tenth of it; the disks' 1x follows the
    linearised rotor on pedestals as closely as it does without them."""
    w = 100.0

    def run(effects):
        sim = R.RotorBearingSimulator(effects=effects)
        tab = sim.simulate(w, fs=1000.0, n_samples=800, settle=1.5)
        phi = w * np.arange(len(tab)) / 1000.0
        one_x = {c: order_components(tab[c].to_numpy(), phi, (1,))[0][0]
                 for c in ("xA", "yA", "xO1", "yO1")}
        return sim, tab, one_x

    _, _, stiff = run([])
    sim, tab, soft = run([R.SupportAnisotropy(kx=2e6, ky=2e6, probes="frame")])
    assert all(soft[c] > 1.2 * stiff[c] for c in ("xA", "yA"))
    assert list(tab.columns) == ["speed", "t", "u", "phi", *R.DOF_NAMES]  # no housings
    linear = sim.linear_model().unbalance_response([w], dof="xO1")["amplitude"].iloc[0]
    assert soft["xO1"] == pytest.approx(linear, rel=0.03)
    _, _, relative = run([R.SupportAnisotropy(kx=2e6, ky=2e6)])
    # the housing follows its journal: the probe reads the contact's deflection, set by
    # the force the (soft) shaft passes to the bearing, not the pedestal's motion
    assert all(relative[c] < 0.1 * soft[c] for c in ("xA", "yA"))
    assert relative["xO1"] == pytest.approx(soft["xO1"], rel=1e-9)  # disks: frame probes


def test_housing_probes_read_the_journal_minus_its_housing():
    """``probes='housing'`` subtracts each housing's displacement from its journal's
    channel, ``'frame'`` leaves it; the disks' channels are untouched (the simulator
    drops the housings' columns after every effect has read them: see
    ``test_a_soft_pedestal_lets_the_journal_move_more``)."""
    rng = np.random.default_rng(0)
    names = ["xA", "yA", "xO1", "xB", "yB", *R.HOUSING_NAMES]
    table = {n: rng.normal(size=50) for n in names}
    out = R.SupportAnisotropy().measure(dict(table), None)
    for journal, housing in (("xA", "xHA"), ("yA", "yHA"), ("xB", "xHB"), ("yB", "yHB")):
        np.testing.assert_array_equal(out[journal], table[journal] - table[housing])
    for name in ("xO1", *R.HOUSING_NAMES):
        np.testing.assert_array_equal(out[name], table[name])
    framed = R.SupportAnisotropy(probes="frame").measure(dict(table), None)
    for name in names:
        np.testing.assert_array_equal(framed[name], table[name])


def test_pedestal_mistakes_are_named():
    with pytest.raises(ValueError, match="probes='shaft' is not one of housing, frame"):
        R.SupportAnisotropy(probes="shaft")
    with pytest.raises(ValueError, match="housing has mass"):
        R.SupportAnisotropy(mass=0.0)
    with pytest.raises(ValueError, match="stiffness must be positive"):
        R.SupportAnisotropy(kx=0.0)
    two = R.RotorBearingSimulator(effects=[R.SupportAnisotropy(), R.SupportAnisotropy()])
    with pytest.raises(ValueError, match="Only one effect may mount the bearings"):
        two.static_equilibrium()
    sim = R.RotorBearingSimulator(effects=[R.SupportAnisotropy()])
    with pytest.raises(ValueError, match="state must be"):
        sim.simulate_columns(100.0, n_samples=10, settle=0.01,
                             state=(np.zeros(13), np.zeros(13)))


def test_a_state_without_housings_continues_on_pedestals():
    """A calibration continues one candidate's settled runs with another's: a 12-DOF
    state starts a rotor on pedestals with its housings at rest on their static
    deflection (and a 16-DOF state a rotor without them, housings dropped)."""
    bare = R.RotorBearingSimulator()
    on = R.RotorBearingSimulator(effects=[R.SupportAnisotropy(kx=1e8, ky=1e8, mass=15.0)])
    state = bare.warm_state(120.0, settle=0.3, lead=0.1)
    cols = on.simulate_columns(120.0, n_samples=100, settle=0.1, state=state)
    assert np.all(np.isfinite(cols["xA"]))
    back = bare.simulate_columns(120.0, n_samples=100, settle=0.1,
                                 state=on.warm_state(120.0, settle=0.3, lead=0.1))
    assert np.all(np.isfinite(back["xO1"]))


def test_each_bearing_and_each_disk_can_have_its_own_values():
    """``kB_B``, ``clearance_B`` and ``e_O2`` left at None are bearing A's and disk O1's
    values, bit for bit; set, they act on bearing B and disk O2 only, in the integrator
    and in the reference solver alike."""
    base = R.RotorParameters()
    same = base.replace(kB_B=base.kB, clearance_B=base.clearance, e_O2=base.e)
    a = R.RotorBearingSimulator(base).simulate_columns(200.0, n_samples=300, settle=0.2)
    b = R.RotorBearingSimulator(same).simulate_columns(200.0, n_samples=300, settle=0.2)
    for dof in R.DOF_NAMES:
        np.testing.assert_array_equal(a[dof], b[dof])
    assert base.bearing("B") == (base.kB, base.clearance) and base.resolved("e_O2") == base.e
    # a softer bearing B sags more under gravity at B, not at A
    soft_b = R.RotorBearingSimulator(base.replace(kB_B=0.3 * base.kB, clearance_B=5e-6))
    q0, q1 = R.RotorBearingSimulator(base).static_equilibrium(), soft_b.static_equilibrium()
    iA, iB = R.DOF_NAMES.index("yA"), R.DOF_NAMES.index("yB")
    assert q1[iB] < q0[iB] - 4e-6 and abs(q1[iA] - q0[iA]) < 0.2 * abs(q1[iB] - q0[iB])
    # disk O2's own eccentricity: the linear unbalance force at O2 scales with it alone
    lin0 = R.RotorBearingSimulator(base).linear_model().unbalance
    lin1 = R.RotorBearingSimulator(base.replace(e_O2=2 * base.e)).linear_model().unbalance
    iO1, iO2 = R.DOF_NAMES.index("xO1"), R.DOF_NAMES.index("xO2")
    assert lin1[iO1] == lin0[iO1] and lin1[iO2] == pytest.approx(2 * lin0[iO2])
    # scaling the unbalance scales both disks, O2's own value where it is set
    assert base.with_unbalance_scaled(2.0).e_O2 is None
    both = base.replace(e_O2=0.5 * base.e).with_unbalance_scaled(2.0)
    assert (both.e, both.e_O2) == (2 * base.e, base.e)
    # the integrator and the independent reference solver agree with distinct bearings
    sim = R.RotorBearingSimulator(base.replace(kB_B=0.5 * base.kB, clearance_B=2e-6,
                                               e_O2=0.7 * base.e))
    _assert_matches_reference(sim, 180.0, 0.5, 250, ("xO2", "yB", "xA"))
    with pytest.raises(ValueError, match="kB_B"):
        base.replace(kB_B=-1.0)
    with pytest.raises(ValueError, match="bearing"):
        base.bearing("C")


def test_a_disk_damper_can_act_to_the_frame():
    """``frame_share_d1``/``_d2`` move a share of each disk damper from across its shaft
    segment to between the disk and the frame; 0 is the model of docs/rotor_model.md,
    bit for bit."""
    from sknarx.rotor.matrices import DOF_INDEX, assemble

    base = R.RotorParameters()
    C0 = assemble(base).C
    assert np.array_equal(assemble(base.replace(frame_share_d1=0.0)).C, C0)
    C1 = assemble(base.replace(frame_share_d1=1.0, frame_share_d2=1.0)).C
    a, o1, o2, b = (DOF_INDEX[n] for n in ("xA", "xO1", "xO2", "xB"))
    assert C1[a, o1] == 0.0 and C1[o2, b] == 0.0  # no damper across the segments
    assert C1[o1, o1] == pytest.approx(C0[o1, o1])  # the disk still sees c_d1
    assert C1[a, a] == pytest.approx(C0[a, a] - base.c_d1)  # the journal no longer
    with pytest.raises(ValueError, match="frame_share_d2"):
        base.replace(frame_share_d2=1.5)


def test_the_joint_dampers_can_act_on_the_disks_tilt():
    """``tilt_share_O`` moves a share of ``c_O1``, ``c_O2`` from the joint to each disk's
    tilt (the second derivation's reading); 0 is docs/rotor_model.md's model bit for bit.
    Read on the tilts, they damp out the disks' lightly damped tilting pair (forward
    795 rad/s at 260 rad/s, 0.2 %)."""
    from sknarx.rotor.matrices import DOF_INDEX, assemble

    base = R.RotorParameters()
    C0 = assemble(base).C
    assert np.array_equal(assemble(base.replace(tilt_share_O=0.0)).C, C0)
    C1 = assemble(base.replace(tilt_share_O=1.0)).C
    o1, o2, t1, t2 = (DOF_INDEX[n] for n in ("xO1", "xO2", "tyO1", "tyO2"))
    assert C1[o1, o2] == 0.0  # nothing left on the joint
    assert C1[t1, t1] == pytest.approx(C0[t1, t1] + base.c_O1)
    assert C1[t2, t2] == pytest.approx(C0[t2, t2] + base.c_O2)

    def light_modes(p):
        m = R.RotorBearingSimulator(p).linear_model().modes(260.0)
        return m[(m["frequency"] < 1000.0) & (m["damping_ratio"] < 0.05)]

    assert len(light_modes(base)) == 2  # the tilting pair, 283 and 795 rad/s
    assert len(light_modes(base.replace(tilt_share_O=1.0))) == 0
    with pytest.raises(ValueError, match="tilt_share_O"):
        base.replace(tilt_share_O=-0.1)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(s1=st.floats(0.0, 1.0), s2=st.floats(0.0, 1.0), c1=st.floats(0.0, 1e4),
       c2=st.floats(0.0, 1e4))
def test_damping_stays_symmetric_and_dissipative_wherever_the_disk_dampers_act(s1, s2,
                                                                               c1, c2):
    from sknarx.rotor.matrices import assemble

    C = assemble(R.RotorParameters(c_d1=c1, c_d2=c2, frame_share_d1=s1,
                                   frame_share_d2=s2)).C
    assert np.array_equal(C, C.T)
    assert np.linalg.eigvalsh(C).min() >= -1e-9 * max(np.abs(C).max(), 1.0)


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-6e-5, 6e-5), y=st.floats(-6e-5, 6e-5), which=st.sampled_from("AB"),
       kB_B=st.floats(5e9, 3e10), clearance_B=st.floats(0.0, 2e-5))
def test_the_compiled_bearing_stiffness_is_the_force_by_force_central_difference(
        x, y, which, kB_B, clearance_B):
    # the compiled loop replaced a Python one over bearing_force_py: the same angles,
    # steps and order of the sums, so the same numbers, not merely close ones
    from sknarx.rotor.bearings import bearing_force_py
    p = R.RotorParameters(kB_B=kB_B, clearance_B=clearance_B)
    h = 1e-3 * max(abs(x), abs(y), p.bearing(which)[1], 1e-7)
    pitch = 2 * np.pi / p.n_balls / p.cage_ratio
    K = np.zeros((2, 2))
    for phi in np.linspace(0.0, pitch, 16, endpoint=False):
        for j, (dx, dy) in enumerate(((h, 0.0), (0.0, h))):
            K[:, j] -= (bearing_force_py(x + dx, y + dy, phi, p, which)
                        - bearing_force_py(x - dx, y - dy, phi, p, which)) / (2 * h)
    np.testing.assert_array_equal(bearing_stiffness(x, y, p, which=which), K / 16)


@settings(max_examples=30, deadline=None)
@given(omega=st.floats(0.0, 4000.0), fs=st.sampled_from([0.05, 1000.0, 20000.0]))
def test_the_step_needs_only_the_eigenproblems_around_the_speed(omega, fs):
    # |lambda|max is sampled lazily at the speeds around the run's: the same steps as
    # interpolating all the samples, from at most two eigenproblems
    sim = R.RotorBearingSimulator()
    n = sim.substeps(fs, omega)
    assert len(sim.__dict__["_lambda_cache"]) <= 2
    ws = np.array(sim.LAMBDA_SPEEDS)
    lam = np.array([sim._linear.max_oscillatory_eigenvalue(w) for w in ws])
    full = float(np.interp(omega, ws, lam, right=lam[-1] * omega / ws[-1]))
    assert n == max(1, int(np.ceil(full / fs / sim.step_factor)))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(depth=st.floats(0.0, 0.6), angle=st.floats(-np.pi, np.pi),
       mean=st.floats(0.7, 1.4), station=st.sampled_from(R.BreathingCrack.STATIONS),
       opening=st.floats(-np.pi, np.pi))
def test_a_cracks_mean_scale_is_its_element_stiffness_over_a_revolution(depth, angle, mean,
                                                                        station, opening):
    # the calibration searches a crack by its mean stiffness (depth then moves only the
    # breathing): the kernel's force averaged over the shaft angle is that of an
    # uncracked element of stiffness mean_scale, wherever the crack opens
    from sknarx.gap.calibration import search_vector
    from sknarx.rotor.effects import EffectContext

    crack = R.BreathingCrack.from_params({"depth": depth, "angle": angle,
                                          "mean_scale": mean, "station": station,
                                          "opening": opening})
    assert crack.mean_scale == pytest.approx(mean)
    np.testing.assert_allclose(search_vector(crack),
                               [depth, angle, np.log10(mean), opening], atol=1e-12)
    ctx = EffectContext(q_static=np.zeros(12), params=R.RotorParameters())
    q = np.random.default_rng(1).normal(size=12) * 1e-5

    def force(effect, phi):
        kernel, p = effect.force_kernel(ctx)
        out = np.zeros(12)
        kernel(0.0, phi, 150.0, 0.0, q, np.zeros(12), p, out)
        return out

    # the breathing force is a trigonometric polynomial of degree 3 in the angle: 16
    # equally spaced angles average it exactly
    phis = 2 * np.pi * np.arange(16) / 16
    mean_force = np.mean([force(crack, f) for f in phis], axis=0)
    uncracked = force(R.BreathingCrack(depth=0.0, element_scale=mean, station=station), 0.0)
    np.testing.assert_allclose(mean_force, uncracked, atol=1e-9 * np.abs(uncracked).max()
                               + 1e-15)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(depth=st.floats(0.05, 0.6), angle=st.floats(-np.pi, np.pi),
       opening=st.floats(-np.pi, np.pi), phi=st.floats(-np.pi, np.pi),
       station=st.sampled_from(R.BreathingCrack.STATIONS))
def test_a_crack_is_open_where_its_normal_points_at_its_opening(depth, angle, opening, phi,
                                                                 station):
    # h = (1 + cos(phi + angle - opening))/2: shut when the normal points away from the
    # opening direction, and two cracks opening on opposite sides share one open crack's
    # force between them at every angle (h + h' = 1)
    from sknarx.rotor.effects import EffectContext

    ctx = EffectContext(q_static=np.zeros(12), params=R.RotorParameters())
    q = np.random.default_rng(2).normal(size=12) * 1e-5

    def force(opening, phi):
        kernel, p = R.BreathingCrack(depth=depth, angle=angle, station=station,
                                     opening=opening).force_kernel(ctx)
        out = np.zeros(12)
        kernel(0.0, phi, 150.0, 0.0, q, np.zeros(12), p, out)
        return out

    scale = np.abs(force(opening, opening - angle)).max()
    assert scale > 0
    np.testing.assert_allclose(force(opening, opening - angle + np.pi), 0.0,
                               atol=1e-12 * scale)
    shared = force(opening, phi) + force(opening + np.pi, phi)
    fully_open = force(phi + angle, phi)  # opening where the normal points now: h = 1
    np.testing.assert_allclose(shared, fully_open, atol=1e-9 * scale)


@settings(max_examples=40, deadline=None)
@given(scale=st.floats(0.5, 2.0), kB_B=st.one_of(st.none(), st.floats(5e9, 2e10)),
       clearance=st.floats(5e-7, 5e-5))
def test_the_clearance_changes_both_bearings_clearance_and_contact_stiffness(scale, kB_B,
                                                                            clearance):
    """The clearance candidate is one change of both bearings: each gets the clearance,
    and each keeps its own contact stiffness times ``contact_scale`` (a bearing B
    that shares A's stiffness keeps sharing it scaled); nothing else moves."""
    params = R.RotorParameters(kB_B=kB_B, clearance_B=2e-6)
    changed = R.ClearanceChange(clearance=clearance, contact_scale=scale).modify_parameters(
        params)
    assert changed.resolved("clearance_B") == changed.clearance == clearance
    assert changed.kB == pytest.approx(params.kB * scale, rel=1e-12)
    assert changed.resolved("kB_B") == pytest.approx(params.resolved("kB_B") * scale,
                                                     rel=1e-12)
    same = {k for k, v in params.to_dict().items() if changed.to_dict()[k] == v}
    assert same >= set(params.to_dict()) - {"clearance", "clearance_B", "kB", "kB_B"}
    # at scale 1 the candidate is the clearance alone, as the simulator's trials draw it
    plain = R.ClearanceChange(clearance=clearance).modify_parameters(params)
    assert plain.kB == params.kB and plain.resolved("kB_B") == params.resolved("kB_B")


@pytest.mark.parametrize("case", ["plain", "crack", "user kernel"])
def test_the_compiled_integrator_is_plain_rk4_of_the_documented_forces(case):
    """The compiled kernel shares trigonometry between RK-4 stages and bearings and sums
    the linear forces column by column; none of that may change what it integrates:
    a plain RK-4 of ``M^-1 (F - (C + Omega G) v - K q)`` with the unbalance, gravity,
    the two bearings' forces and the effect's kernel, over a speed ramp (angular
    acceleration on), must give the same states to rounding. Both entry points: the
    cached one of the package's own forces and the hooked one of a user's kernel."""
    from sknarx.rotor.bearings import bearing_force
    from sknarx.rotor.effects import builtin_forces
    from sknarx.rotor.integrator import integrate
    from sknarx.testing import ThermalBow

    effects = {"plain": (), "crack": (R.effects.BreathingCrack(),),
               "user kernel": (R.effects.BreathingCrack(), ThermalBow(bow=1e-4))}[case]
    sim = R.RotorBearingSimulator(effects=effects)
    assert (sim._setup.kernel is builtin_forces) == (case != "user kernel")
    s = sim._setup
    unb, brg = s.unb, s.brg
    fs, substeps, n = 1000.0, 3, 25
    omega = np.linspace(140.0, 170.0, n + 1)
    q0 = s.context.q_static.copy()
    v0 = np.zeros_like(q0)

    def accel(t, phi, w, al, q, v):
        f = s.fg.copy()
        for d in range(2):
            me, ph, ix, iy = unb[d, 0], unb[d, 1], int(unb[d, 2]), int(unb[d, 3])
            f[ix] += me * (w * w * np.cos(phi + ph) + al * np.sin(phi + ph))
            f[iy] += me * (w * w * np.sin(phi + ph) - al * np.cos(phi + ph))
        for b, (kB, gamma) in enumerate([(brg[0], brg[1]), (brg[9], brg[10])]):
            ix, iy = int(brg[5 + 2 * b]), int(brg[6 + 2 * b])
            fx, fy = bearing_force(q[ix], q[iy], phi, kB, gamma, brg[2], int(brg[3]), brg[4])
            f[ix] += fx
            f[iy] += fy
        s.kernel(t, phi, w, al, q, v, s.kparams, f)
        return s.minv * (f - (s.C + w * s.G) @ v - s.K @ q)

    dt = 1.0 / fs
    h = dt / substeps
    q, v, phi = q0.copy(), v0.copy(), 0.0
    expected = [q.copy()]
    for k in range(n):
        wk, al = omega[k], (omega[k + 1] - omega[k]) / dt
        for sub in range(substeps):
            tau = sub * h
            ta, wa = k * dt + tau, wk + al * tau
            pa = phi + wk * tau + 0.5 * al * tau**2
            stages = [(ta, pa, wa), (ta + h / 2, pa + wa * h / 2 + al * h * h / 8, wa + al * h / 2),
                      (ta + h / 2, pa + wa * h / 2 + al * h * h / 8, wa + al * h / 2),
                      (ta + h, pa + wa * h + al * h * h / 2, wa + al * h)]
            kq, kv = [], []
            for i, (tt, pp, ww) in enumerate(stages):
                c = (0.0, 0.5, 0.5, 1.0)[i]
                qi = q + c * h * kq[-1] if i else q
                vi = v + c * h * kv[-1] if i else v
                kq.append(vi)
                kv.append(accel(tt, pp, ww, al, qi, vi))
            q = q + h / 6 * (kq[0] + 2 * kq[1] + 2 * kq[2] + kq[3])
            v = v + h / 6 * (kv[0] + 2 * kv[1] + 2 * kv[2] + kv[3])
        phi += 0.5 * (wk + omega[k + 1]) * dt
        expected.append(q.copy())
    Q, *_ = integrate(q0, v0, omega, 0.0, 0.0, dt, substeps, 0, s.minv, s.C, s.G, s.K, s.fg,
                      unb, brg, s.kernel, s.kparams, 1.0)
    expected = np.array(expected)
    np.testing.assert_allclose(Q, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    # the run moved: the comparison is not of the start state with itself
    assert np.abs(expected[-1] - expected[0]).max() > 1e-3 * np.abs(expected).max()
