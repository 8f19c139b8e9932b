"""A tour of the simulator: linear analysis, sweeps on disk, run-ups and extra physics.

Run: python examples/03_simulator_tour.py
"""

import tempfile

import numpy as np

from sknarx.orders import order_components
from sknarx.rotor import (
    ProbeRunout,
    RotorBearingSimulator,
    RotorParameters,
    Rub,
    load_sweep,
)

sim = RotorBearingSimulator(RotorParameters())  # Table 1 and 2 defaults, SI units
lin = sim.linear_model()
print("first forward critical speed (1x crossing):", lin.critical_speeds(500.0)[0], "rad/s")
print(lin.modes(150.0).head(4))

with tempfile.TemporaryDirectory() as tmp:
    # each finished speed is written atomically; rerunning resumes
    sim.sweep([100.0, 150.0, 200.0], fs=1000.0, n_samples=2048, path=f"{tmp}/sweep",
              progress=False)
    table = load_sweep(f"{tmp}/sweep")
    print(table.groupby("speed").xO1.agg(lambda x: (x.max() - x.min()) / 2))

run = sim.run_up(lambda t: 80.0 + 10.0 * t, fs=1000.0, duration=10.0, settle=1.0)
print("run-up to", run.speed.iloc[-1], "rad/s, peak |xO1|", run.xO1.abs().max(), "m")

rubbing = RotorBearingSimulator(effects=[Rub(clearance=8e-4, stiffness=2e7, friction=0.1),
                                         ProbeRunout(amplitude=5e-6)])
r = rubbing.simulate(144.5, fs=1000.0, n_samples=4096)
amp = order_components(r.xO1, r.phi, (1, 2, 3))[0]
print("with rub and runout, orders 1-3 at xO1 (m):", np.array2string(amp, precision=3))
