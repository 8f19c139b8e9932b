"""Test equipment: synthetic measurements from sknarx's own simulator with an effect
withheld, for tests, examples and trying the gap diagnosis.

Not part of the modelling or diagnosis pipeline, and not a validation: a trial is
simulated by the same code the diagnosis fits with (the "inverse crime"); the blind
validation on plants independent of ``sknarx.rotor`` is ``validation/`` (docs/validation.md).

A trial draws an effect (or none, a pair, or an effect outside the library), its
severity and parameters, rig-like nuisance mismatch (a few percent of stiffness,
damping and unbalance, an unknown unbalance phase), measurement noise (SNR 20-40
dB) and once-per-revolution jitter, and simulates the stepped-speed test. The
diagnoser sees only the table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .rotor import (
    EFFECTS,
    Effect,
    MeasurementNoise,
    RotorBearingSimulator,
    RotorParameters,
)

__all__ = ["LineFrequency", "ThermalBow", "make_trial", "sample_effect", "TRIAL_SPEEDS"]

TRIAL_SPEEDS = tuple(np.linspace(81.7, 276.5, 10).round(4))
CHANNELS = ("xO1", "yO1", "xA", "yA")


@dataclass(repr=False)
class LineFrequency(Effect):
    """Out of library: electrical pickup at a fixed line frequency on every probe."""

    amplitude: float = 2e-5
    frequency: float = 50.0
    name = "line-frequency"

    def measure(self, table, rng, context=None):
        for c in CHANNELS:
            if c in table:
                table[c] = table[c] + self.amplitude * np.sin(2 * np.pi * self.frequency *
                                                              np.asarray(table["t"]))
        return table


@njit(nogil=True, cache=True)
def _bow_kernel(t, phi, omega, alpha, q, v, p, out):  # pragma: no cover
    out[2] += p[0] * math.cos(phi + p[1])
    out[3] += p[0] * math.sin(phi + p[1])


@dataclass(repr=False)
class ThermalBow(Effect):
    """Out of library: a bowed shaft at disk O1 -- a 1x force k1 * bow, independent of speed."""

    bow: float = 1e-4
    angle: float = 1.0
    name = "thermal-bow"

    def force_kernel(self, context):
        return _bow_kernel, np.array([context.params.k1 * self.bow, self.angle])


def _log_uniform(rng, a, b):
    return float(10 ** rng.uniform(np.log10(a), np.log10(b)))


def sample_effect(name: str, rng) -> Effect:
    """A random, typically detectable, instance of an effect."""
    if name == "rub":
        return EFFECTS[name](clearance=rng.uniform(6e-4, 9.5e-4),
                             stiffness=_log_uniform(rng, 1e6, 1e7),
                             friction=rng.uniform(0.0, 0.2))
    if name == "misalignment":
        return EFFECTS[name](parallel=rng.uniform(1e-4, 6e-4), angular=rng.uniform(0, 2e-3))
    if name == "crack":
        return EFFECTS[name](depth=rng.uniform(0.15, 0.5), angle=rng.uniform(-np.pi, np.pi))
    if name == "looseness":
        return EFFECTS[name](residual=_log_uniform(rng, 1e-3, 2e-2), gap=rng.uniform(0, 4e-6))
    if name == "clearance":
        return EFFECTS[name](clearance=_log_uniform(rng, 8e-6, 4e-5))
    if name == "anisotropy":
        soft, stiff = _log_uniform(rng, 2e6, 1.5e7), _log_uniform(rng, 8e7, 8e8)
        kx, ky = (soft, stiff) if rng.random() < 0.5 else (stiff, soft)
        return EFFECTS[name](kx=kx, ky=ky)
    if name == "runout":
        return EFFECTS[name](amplitude=rng.uniform(1e-5, 6e-5), phase=rng.uniform(-np.pi, np.pi))
    if name == "speed-fluctuation":
        return EFFECTS[name](amplitude=rng.uniform(0.005, 0.03),
                             frequency=_log_uniform(rng, 1.0, 8.0))
    if name == "line-frequency":
        return LineFrequency(amplitude=rng.uniform(1e-5, 5e-5), frequency=50.0)
    if name == "thermal-bow":
        return ThermalBow(bow=rng.uniform(5e-5, 2e-4), angle=rng.uniform(-np.pi, np.pi))
    raise ValueError(f"Unknown effect {name!r}.")


def make_trial(kind, seed: int, speeds=TRIAL_SPEEDS, fs=1000.0, n_samples=1000,
               base: RotorParameters | None = None):
    """Simulate one blind trial.

    Parameters
    ----------
    kind : None, str or tuple of str
        ``None`` (effect-free), an effect name, or a pair of names.

    Returns
    -------
    measured : DataFrame
    truth : dict
        The withheld answer: effects, their parameters, nuisance values, noise.
    """
    from .rotor import SimulationDivergenceError

    base = base or RotorParameters()
    names = () if kind is None else ((kind,) if isinstance(kind, str) else tuple(kind))
    # a drawn effect can make the rotor physically unstable (e.g. rub with strong
    # friction): redraw it, as a rig would have been stopped
    for attempt in range(5):
        rng = np.random.default_rng([seed, attempt])
        try:
            return _trial(names, rng, seed, speeds, fs, n_samples, base)
        except SimulationDivergenceError:
            continue
    raise RuntimeError(f"no stable draw of {kind} for seed {seed}")


def _trial(names, rng, seed, speeds, fs, n_samples, base):
    effects = [sample_effect(n, rng) for n in names]
    nuis = {"stiffness_scale": rng.uniform(0.97, 1.03), "damping_scale": rng.uniform(0.95, 1.05),
            "unbalance_scale": rng.uniform(0.95, 1.05),
            "unbalance_phase": rng.uniform(-np.pi, np.pi)}
    b = base
    sc = nuis["damping_scale"]
    params = b.with_unbalance_scaled(nuis["unbalance_scale"]).replace(
        unbalance_phase=nuis["unbalance_phase"],
        k1=b.k1 * nuis["stiffness_scale"], k2=b.k2 * nuis["stiffness_scale"],
        c_a=b.c_a * sc, c_b=b.c_b * sc, c_d1=b.c_d1 * sc, c_d2=b.c_d2 * sc, c_O1=b.c_O1 * sc,
        c_O2=b.c_O2 * sc)
    snr = rng.uniform(20.0, 40.0)
    sim = RotorBearingSimulator(params, effects=effects + [MeasurementNoise(snr_db=snr)],
                                seed=seed)
    table = sim.sweep(list(speeds), fs=fs, n_samples=n_samples, settle=0.0, progress=False)
    jitter = rng.uniform(-2.0, 2.0, len(speeds))  # degrees of keyphasor error per step
    offsets = dict(zip(speeds, np.radians(jitter) / np.asarray(speeds), strict=True))
    table["t"] = table["t"] - table["speed"].map(offsets)
    measured = table[["speed", "t", *CHANNELS]].copy()
    truth = {"kind": "none" if not names else (names[0] if len(names) == 1 else list(names)),
             "effects": [{"name": e.name, **e.to_dict()} for e in effects],
             "nuisance": nuis, "snr_db": snr, "jitter_deg": jitter.tolist(),
             "in_library": all(n in EFFECTS for n in names)}
    return measured, truth


def oracle_gap(measured, truth, heldout, channels=CHANNELS, transient_s=0.5, base=None):
    """Held-out excess gap of the true model (true effects, true nuisance values)."""
    from .gap.calibration import Calibration, heldout_gap
    from .gap.measured import check_measured
    from .gap.sweep_model import SweepModel
    from .orders import order_features

    measured, info = check_measured(measured, list(channels))
    model = SweepModel(base=base or RotorParameters(), fs=info["fs"],
                       n_samples=info["n_samples"], channels=tuple(channels),
                       transient_s=transient_s)
    effects = [EFFECTS[e["name"]](**{k: v for k, v in e.items() if k != "name"})
               for e in truth["effects"] if e["name"] in EFFECTS]
    n = truth["nuisance"]
    cal = Calibration(names=tuple(type(e).name for e in effects),
                      effect_params=[e.to_dict() for e in effects],
                      nuisance={"unbalance_scale": n["unbalance_scale"],
                                "unbalance_phase": n["unbalance_phase"],
                                "stiffness_scale": n["stiffness_scale"],
                                "damping_scale": n["damping_scale"]},
                      std={}, cost=0.0, n_params=0, success=True)
    meas = order_features(measured, list(channels), transient_s)
    E, _ = heldout_gap(model, meas, np.asarray(heldout), cal, [type(e) for e in effects])
    return E
