"""Two passes of one sweep: a run-up, then the coast-down after it.

A hot rotor's thermal bow relaxes while it runs. On a run-up alone, whose speeds only
rise, the relaxation is a smooth change of 1x over speed, which the nominal model update
absorbs. The coast-down meets every speed again at another thermal state, so the two
passes disagree where no time-invariant effect can make them disagree.

Run: python examples/06_two_passes.py
"""

import numpy as np
import pandas as pd

from sknarx.gap import compare_passes, diagnose
from sknarx.rotor import MeasurementNoise, RotorBearingSimulator
from sknarx.testing import ThermalBow

SPEEDS = np.linspace(81.7, 276.5, 6).round(4)  # rad/s
CHANNELS = ["xO1", "yO1", "xA", "yA", "xB", "yB"]  # m
BOW_M, RELAX_STEPS = 1.2e-4, 4.0  # the bow at the first step (m) and its decay (steps)


def step(speed, k, seed):
    """The settled record of the ``k``-th step of the test, at ``speed`` (rad/s)."""
    bow = ThermalBow(bow=BOW_M * np.exp(-k / RELAX_STEPS), angle=1.0)
    sim = RotorBearingSimulator(effects=[bow, MeasurementNoise(snr_db=30.0)], seed=seed)
    run = sim.simulate(float(speed), fs=1000.0, n_samples=1000, settle=2.0)
    return run[["speed", "t", *CHANNELS]]


n = len(SPEEDS)
run_up = pd.concat([step(w, k, seed=k) for k, w in enumerate(SPEEDS)], ignore_index=True)
# the coast-down visits the speeds from the top, its steps counted on from the run-up's
coast_down = pd.concat([step(w, 2 * n - 1 - i, seed=100 + i) for i, w in enumerate(SPEEDS)],
                       ignore_index=True)

passes = compare_passes(run_up, coast_down)
top = passes.to_dict()["largest"][0]
print(f"the passes differ: {passes.changed} (a normal deviate of {passes.statistic:.0f} "
      f"beyond the dead band; floor {passes.floor:.2f})")
print(f"most at {top['feature']} on {top['channel']} at {top['speed']:.1f} rad/s: "
      f"{1e6 * top['first_m']:.1f} um up, {1e6 * top['second_m']:.1f} um down")

result = diagnose(run_up, candidates=("runout",), second_pass=coast_down)
print("verdict with both passes:", result["verdict"])
print("the run-up alone said:", result["passes"]["one_pass"]["verdict"])
