"""Blind trials from three plant families, drawn the same way for each.

A trial is a draw -- the effect(s) or none, their physical parameters, a rig-like
per-element mismatch, noise and keyphasor jitter -- that each family turns into a
stepped, settled sweep in the measured-file format through its own simulation code:

* ``own``: ``sknarx.rotor.RotorBearingSimulator`` with its own effect kernels (the
  "own-model" upper bound);
* ``second``: ``plants.second_derivation`` (housings with mass, other readings of the
  paper, effects written from their sources);
* ``ross``: ``plants.ross_paper_rotor`` (ROSS finite elements and integrator, ROSS's
  crack, misalignment and rubbing models).

The measurement chain (per-probe runout, a line-frequency pickup, noise, jitter) is
written here, once, for all families. What a family cannot express is listed in
``UNSUPPORTED`` and not drawn for it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

CHANNELS = ("xO1", "yO1", "xA", "yA", "xB", "yB")
SPEEDS = tuple(np.linspace(81.7, 276.5, 10).round(4))
LIB = ["rub", "misalignment", "crack", "looseness", "clearance", "anisotropy", "runout",
       "speed-fluctuation"]
PAIRS = [("crack", "runout"), ("anisotropy", "runout"), ("clearance", "misalignment"),
         ("crack", "speed-fluctuation")]
OUT = ["line-frequency", "thermal-bow", "gear-mesh", "cage-fault"]
MEASUREMENT = ("runout", "line-frequency")
FAMILIES = ("own", "second", "ross")
#: what a family cannot express: sknarx's simulator has no gear mesh and no cage fault
#: (kept out of the own family, whose out-of-library effects are the line pickup and
#: the thermal bow); ROSS has no joint looseness (see plants.ross_paper_rotor)
UNSUPPORTED = {"own": {"gear-mesh", "cage-fault"}, "second": set(), "ross": {"looseness"}}


def _log_uniform(rng, a, b):
    return float(10 ** rng.uniform(np.log10(a), np.log10(b)))


def draw_effect(name, rng):
    """Physical parameters of one effect (SI, family-independent)."""
    u = rng.uniform
    if name == "crack":
        return {"depth": u(0.15, 0.5), "angle": u(-np.pi, np.pi),
                "station": str(rng.choice(["A-O1", "O2-B"]))}
    if name == "rub":
        return {"clearance": u(6e-4, 9.5e-4), "stiffness": _log_uniform(rng, 1e6, 1e7),
                "friction": u(0.0, 0.2), "at": str(rng.choice(["O1", "O2"]))}
    if name == "misalignment":
        return {"parallel": u(1e-4, 6e-4), "angular": u(0.0, 2e-3),
                "at": str(rng.choice(["A", "B"]))}
    if name == "looseness":
        return {"residual": _log_uniform(rng, 1e-3, 2e-2), "gap": u(0.0, 4e-6)}
    if name == "clearance":
        return {"clearance": _log_uniform(rng, 8e-6, 4e-5)}
    if name == "anisotropy":
        soft = _log_uniform(rng, 5e6, 5e7)
        return {"soft": soft, "soft_axis": str(rng.choice(["x", "y"]))}
    if name == "speed-fluctuation":
        # speed Omega (1 + amplitude cos(2 pi frequency t + phase)), t each record's time
        return {"amplitude": u(0.005, 0.03), "frequency_hz": _log_uniform(rng, 1.0, 8.0),
                "phase": u(-np.pi, np.pi)}
    if name == "runout":
        return {ch: [u(5e-6, 4e-5), u(-np.pi, np.pi), u(0.0, 0.3), u(-np.pi, np.pi)]
                for ch in CHANNELS}
    if name == "line-frequency":
        return {"amplitude": u(1e-5, 5e-5), "frequency_hz": 50.0}
    if name == "thermal-bow":
        # a hot rotor's bow relaxing as it turns (the thermal state evens out): the bow
        # of the k-th speed step is bow * exp(-k / relax_steps). A bow the same at every
        # step is runout plus the disks' unbalance to 2-3 % in 1x on every family
        # (docs/decisions.md): in the library, not out of it
        return {"bow": u(5e-5, 2e-4), "angle": u(-np.pi, np.pi), "relax_steps": u(2.0, 8.0)}
    if name == "gear-mesh":
        return {"force": u(20.0, 100.0), "angle": u(-np.pi, np.pi)}
    if name == "cage-fault":
        # a damaged cage (a broken pocket, balls bunched) carries the bearing's load
        # unevenly: a force turning with the cage, at its order (about 0.4x), on one
        # bearing's journal -- a non-synchronous line locked to the shaft's order, which
        # no library effect makes (the clearance's ball passage is nb times it)
        return {"force": _log_uniform(rng, 10.0, 100.0), "angle": u(-np.pi, np.pi),
                "at": str(rng.choice(["A", "B"]))}
    raise ValueError(f"unknown effect {name!r}")


def draw_trial(kind, seed, family):
    """The withheld truth of one trial: effects, mismatch, noise, jitter."""
    rng = np.random.default_rng([seed, FAMILIES.index(family)])
    names = () if kind is None else ((kind,) if isinstance(kind, str) else tuple(kind))
    u = rng.uniform
    mismatch = {"k1": u(0.95, 1.05), "k2": u(0.95, 1.05),
                **{c: u(0.8, 1.2) for c in ("c_a", "c_b", "c_d1", "c_d2", "c_O1", "c_O2")},
                "kB_A": u(0.8, 1.2), "kB_B": u(0.8, 1.2),
                "e_O1": u(0.9, 1.1), "e_O2": u(0.9, 1.1),
                "unbalance_phase": u(-np.pi, np.pi), "beta_error": np.radians(u(-10, 10))}
    return {"kind": "none" if not names else (names[0] if len(names) == 1 else list(names)),
            "family": family, "seed": seed,
            "effects": {n: draw_effect(n, rng) for n in names},
            "mismatch": mismatch, "snr_db": u(20.0, 40.0),
            "jitter_deg": u(-2.0, 2.0, len(SPEEDS)).tolist(),
            "noise_seed": int(rng.integers(2**31)),
            "in_library": all(n in LIB for n in names)}


# ------------------------------------------------------------------ the families
# Each family's sweep: ``speeds`` None is the module's SPEEDS read at call time
# (the cost benchmark sets 19 steps there); a relaxing bow passes one step at a time.
def _own_sweep(truth, physical, settle, plant=None, speeds=None):
    from sknarx.rotor import EFFECTS, RotorBearingSimulator, RotorParameters

    # ``plant``: RotorParameters fields set after the mismatch (a variant for analysis)
    m, b = truth["mismatch"], RotorParameters()
    params = b.replace(
        k1=b.k1 * m["k1"], k2=b.k2 * m["k2"],
        **{c: getattr(b, c) * m[c] for c in ("c_a", "c_b", "c_d1", "c_d2", "c_O1", "c_O2")},
        kB=b.kB * m["kB_A"], kB_B=b.kB * m["kB_B"], e=b.e * m["e_O1"], e_O2=b.e * m["e_O2"],
        unbalance_phase=m["unbalance_phase"], beta=b.beta + m["beta_error"],
        **(plant or {}))
    effects = []
    for name, p in physical.items():
        if name == "crack":
            effects.append(EFFECTS[name](depth=p["depth"], angle=p["angle"],
                                         station=p["station"]))
        elif name == "rub":
            effects.append(EFFECTS[name](clearance=p["clearance"], stiffness=p["stiffness"],
                                         friction=p["friction"], at=p["at"]))
        elif name == "misalignment":
            effects.append(EFFECTS[name](parallel=p["parallel"], angular=p["angular"],
                                         at=p["at"]))
        elif name == "looseness":
            effects.append(EFFECTS[name](residual=p["residual"], gap=p["gap"]))
        elif name == "clearance":
            effects.append(EFFECTS[name](clearance=p["clearance"]))
        elif name == "anisotropy":
            # sknarx's pedestals: the other two plants' housings (15 kg, 5 % damping of
            # the soft pedestal's housing mode), the stiff direction as ROSS's
            stiff = 1e9
            kx, ky = (p["soft"], stiff) if p["soft_axis"] == "x" else (stiff, p["soft"])
            effects.append(EFFECTS[name](kx=kx, ky=ky, mass=15.0,
                                         damping=0.1 * np.sqrt(p["soft"] * 15.0)))
        elif name == "speed-fluctuation":
            # sknarx's ripple is a sine: a quarter turn ahead of the draw's cosine
            effects.append(EFFECTS[name](amplitude=p["amplitude"],
                                         frequency=p["frequency_hz"],
                                         phase=p.get("phase", 0.0) + 0.5 * np.pi))
        elif name == "thermal-bow":
            from sknarx.testing import ThermalBow

            effects.append(ThermalBow(bow=p["bow"], angle=p["angle"]))
    sim = RotorBearingSimulator(params, effects=effects)
    return sim.sweep(list(speeds or SPEEDS), fs=1000.0, n_samples=1000, settle=settle,
                     progress=False)


def _second_sweep(truth, physical, settle, plant=None, speeds=None):
    from .second_derivation import SecondDerivationPlant, SecondRotor

    # ``plant``: SecondRotor fields that differ from the family's plant (a variant for
    # analysis; the mismatch is drawn on top of them)
    m, r = truth["mismatch"], SecondRotor(**(plant or {}))
    rotor = dataclasses.replace(r,
        k1=r.k1 * m["k1"], k2=r.k2 * m["k2"],
        **{c: getattr(r, c) * m[c] for c in ("c_a", "c_b", "c_d1", "c_d2", "c_O1", "c_O2")},
        kB_A=r.kB_A * m["kB_A"], kB_B=r.kB_B * m["kB_B"],
        e_O1=r.e_O1 * m["e_O1"], e_O2=r.e_O2 * m["e_O2"],
        phase_O1=m["unbalance_phase"], phase_O2=m["unbalance_phase"] + r.phase_O2
        + m["beta_error"])
    eff = {}
    for name, p in physical.items():
        if name == "crack":
            # Mayes & Davies: lost stiffness ~ depth ratio (normal) and a quarter of it
            eff[name] = [0 if p["station"] == "A-O1" else 1, 0.8 * p["depth"],
                         0.2 * p["depth"], p["angle"]]
        elif name == "rub":
            eff[name] = [0 if p["at"] == "O1" else 1, p["clearance"], p["stiffness"],
                         p["friction"]]
        elif name == "misalignment":
            # a flexible coupling of 5e5 N/m radial stiffness; the angular part acts
            # through its 0.1 m half-length
            kc_delta = 5e5 * (p["parallel"] + 0.1 * p["angular"])
            eff[name] = [0 if p["at"] == "A" else 1, kc_delta, 0.0]
        elif name == "looseness":
            eff[name] = [p["residual"], p["gap"]]
        elif name == "clearance":
            eff[name] = [p["clearance"]]
        elif name == "anisotropy":
            eff[name] = ([p["soft"], rotor.k_py] if p["soft_axis"] == "x"
                         else [rotor.k_px, p["soft"]])
        elif name == "speed-fluctuation":
            eff[name] = [p["amplitude"], 2 * np.pi * p["frequency_hz"], p.get("phase", 0.0)]
        elif name == "thermal-bow":
            eff[name] = [p["bow"], p["angle"]]
        elif name == "gear-mesh":
            eff[name] = [p["force"], p["angle"]]
        elif name == "cage-fault":
            eff[name] = [0 if p["at"] == "A" else 1, p["force"], p["angle"]]
    rotor.effects = eff
    return SecondDerivationPlant(rotor).sweep(speeds or SPEEDS, CHANNELS, settle=settle)


def _ross_sweep(truth, physical, settle, plant=None, speeds=None):
    from .ross_paper_rotor import ross_sweep

    # ``plant``: PaperRotorROSS fields of a variant (analysis; the benchmark sets none)
    return ross_sweep(truth, physical, speeds or SPEEDS, CHANNELS, settle=settle,
                      plant=plant)


_SWEEP = {"own": (_own_sweep, 2.0), "second": (_second_sweep, 1.5), "ross": (_ross_sweep, 1.0)}


def time_varying(physical):
    """Whether an effect of ``physical`` changes from step to step (the relaxing bow)."""
    return "relax_steps" in physical.get("thermal-bow", {})


def simulate(family, truth, physical, plant=None, pass_index=0):
    """The clean stepped sweep of ``family`` with the ``physical`` effects (SI).

    Every family's steps are settled independently, so an effect that changes from
    step to step -- the relaxing thermal bow -- is simulated step by step with that
    step's value; everything else in one sweep. ``pass_index`` 1 is the coast-down
    right after the run-up (:func:`make_family_passes`): its steps run from the highest
    speed down, and the bow goes on relaxing, step ``2 n - 1 - i`` at the ``i``-th
    speed of ``n``; a time-invariant plant's coast-down is its run-up.
    """
    import pandas as pd

    sweep, settle = _SWEEP[family]
    bow = physical.get("thermal-bow")
    if not time_varying(physical):
        return sweep(truth, physical, settle, plant)
    steps = []
    n = len(SPEEDS)
    for i, w in enumerate(SPEEDS):
        k = i if pass_index == 0 else 2 * n - 1 - i
        now = dict(bow, bow=bow["bow"] * np.exp(-k / bow["relax_steps"]))
        steps.append(sweep(truth, {**physical, "thermal-bow": now}, settle, plant,
                           speeds=(w,)))
    return pd.concat(steps, ignore_index=True)


def measure(clean, truth):
    """The measurement chain on a clean sweep: runout, line pickup, noise, jitter."""
    rng = np.random.default_rng(truth["noise_seed"])
    out = clean.copy()
    t = out["t"].to_numpy()
    phi = out["speed"].to_numpy() * t
    ro = truth["effects"].get("runout")
    lf = truth["effects"].get("line-frequency")
    for ch in CHANNELS:
        y = out[ch].to_numpy().copy()
        if ro is not None:
            a1, p1, r2, p2 = ro[ch]
            y += a1 * np.cos(phi + p1) + r2 * a1 * np.cos(2 * phi + p2)
        if lf is not None:
            y += lf["amplitude"] * np.sin(2 * np.pi * lf["frequency_hz"] * t)
        # noise at the drawn SNR of each channel's vibration (its mean removed per step)
        ac = y - out.groupby("speed")[ch].transform("mean").to_numpy()
        sigma = np.sqrt(np.mean(ac**2)) / 10 ** (truth["snr_db"] / 20)
        out[ch] = y + rng.normal(0.0, sigma, y.size)
    # keyphasor jitter: each step's time axis off by a few degrees of shaft angle
    offs = dict(zip(SPEEDS, np.radians(truth["jitter_deg"]) / np.asarray(SPEEDS),
                    strict=True))
    out["t"] = out["t"] - out["speed"].map(offs)
    return out


def make_family_trial(kind, seed, family, plant=None, second_pass=False):
    """Measured sweep, truth, and the clean sweeps with and without the effects; with
    ``second_pass``, the measured coast-down after it too (:func:`make_family_passes`),
    fifth.

    ``plant``: fields of the family's plant to change (``own``: ``RotorParameters``;
    ``second``: ``SecondRotor``; ``ross``: ``PaperRotorROSS``, e.g. its
    ``crack_form``); for analysing what of a gap a plant's reading causes -- the
    benchmark never sets it.
    """
    truth = draw_trial(kind, seed, family)
    physical = {n: p for n, p in truth["effects"].items() if n not in MEASUREMENT}
    clean = simulate(family, truth, physical, plant)
    clean_free = simulate(family, truth, {}, plant) if physical else clean
    measured = measure(clean, truth)
    # the clean truth for the oracle: the plant with its effects, measurement effects on
    # top but no noise (the oracle knows every effect, not the noise)
    no_noise = dict(truth, snr_db=400.0, jitter_deg=truth["jitter_deg"])
    oracle = measure(clean, no_noise)
    free = measure(clean_free, dict(no_noise, effects={}))
    out = (measured[["speed", "t", *CHANNELS]], truth, oracle, free)
    return (*out, coast_down(family, truth, physical, clean, plant)) if second_pass else out


def second_pass_draw(truth):
    """The second pass's own keyphasor jitter and noise (the plant, its runout and line
    pickup are the first pass's): drawn from a stream of their own, so the first pass
    is the trial's measurement bit for bit."""
    rng = np.random.default_rng([truth["seed"], FAMILIES.index(truth["family"]), 1])
    return {"jitter_deg": rng.uniform(-2.0, 2.0, len(SPEEDS)).tolist(),
            "noise_seed": int(rng.integers(2**31))}


def make_family_passes(kind, seed, family, plant=None):
    """The trial's measured sweep (as :func:`make_family_trial`), a second pass of it --
    the coast-down right after the run-up, every step settled as in the first -- and
    the truth. Only a time-varying effect (:func:`time_varying`) makes the two passes
    differ by more than their noise and jitter."""
    truth = draw_trial(kind, seed, family)
    physical = {n: p for n, p in truth["effects"].items() if n not in MEASUREMENT}
    clean = simulate(family, truth, physical, plant)
    return (measure(clean, truth)[["speed", "t", *CHANNELS]],
            coast_down(family, truth, physical, clean, plant), truth)


def coast_down(family, truth, physical, clean, plant=None):
    """The measured coast-down of a trial whose run-up's clean sweep is ``clean`` (its
    ``physical`` effects, as :func:`simulate` takes them): the same sweep where nothing
    varies in time, else simulated on (see :func:`simulate`), measured with its own
    jitter and noise (:func:`second_pass_draw`)."""
    down = simulate(family, truth, physical, plant, pass_index=1) \
        if time_varying(physical) else clean
    return measure(down, dict(truth, **second_pass_draw(truth)))[["speed", "t", *CHANNELS]]


def runout_vectors(effects):
    """The probes' runout of ``effects`` (a truth's, as :func:`measure` applies it) as
    order vectors ``{channel: {order: complex}}`` (m), the form the comparison leaves
    out of its tolerances (``sknarx.gap.gapmap.compare``); None without a runout."""
    ro = effects.get("runout")
    if ro is None:
        return None
    return {ch: {1.0: a1 * np.exp(1j * p1), 2.0: r2 * a1 * np.exp(1j * p2)}
            for ch, (a1, p1, r2, p2) in ro.items()}


def feature_gap(measured, predicted, speeds, effects=None):
    """Held-out excess gap (the diagnosis's statistic) of ``predicted`` records, which
    hold the measurement effects of ``effects`` (a truth's): their runout is compared as
    the diagnosis compares a fitted one, its vectors kept out of the tolerances."""
    from sknarx.gap.gapmap import compare, gap_statistic
    from sknarx.orders import order_features

    m = order_features(measured, list(CHANNELS), 0.0)
    p = order_features(predicted, list(CHANNELS), 0.0)
    cmp = compare(m[m.speed.isin(speeds)], p[p.speed.isin(speeds)],
                  probe_vectors=runout_vectors(effects or {}))
    return gap_statistic(cmp), len(cmp)


def order_phasors(sweep, orders=(1.0,)):
    """Each step's shaft-order vectors per channel (m, complex, ``x ~ Re(z e^{i k Omega
    t})``), shaped speeds x channels x orders, by the package's least-squares order fit."""
    from sknarx.orders import order_components

    out = np.empty((len(SPEEDS), len(CHANNELS), len(orders)), complex)
    for i, w in enumerate(SPEEDS):
        rec = sweep[sweep.speed == w]
        phi = w * rec["t"].to_numpy()
        for j, ch in enumerate(CHANNELS):
            amp, ph = order_components(rec[ch].to_numpy(), phi, orders)
            out[i, j] = amp * np.exp(1j * ph)
    return out
