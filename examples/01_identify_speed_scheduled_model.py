"""Identify a speed-scheduled NARX model of the paper's rotor and free-run it at a new speed.

Run: python examples/01_identify_speed_scheduled_model.py
"""

import numpy as np

from sknarx import SpeedScheduledNarx, nrmse
from sknarx.orders import order_components
from sknarx.rotor import RotorBearingSimulator

sim = RotorBearingSimulator()
speeds = np.linspace(81.7, 276.5, 19)  # rad/s
# Records that start from rest: the transient makes the dynamics identifiable.
sweep = sim.sweep(speeds, fs=1000.0, n_samples=8192, settle=0.0, progress=False)
data = [(g["u"].to_numpy(), g["xO1"].to_numpy()) for _, g in sweep.groupby("speed")]

model = SpeedScheduledNarx(ny=3, nu=3, degree=3, max_terms=10, esr=0.0, prune=False,
                           speed_basis="spline").fit(data, speeds)
print("selected terms:", model.selected_terms_)
print("AERR (%):", np.round(model.aerr_, 8))

w = 138.2  # never seen in training
run = sim.simulate(w, fs=1000.0, n_samples=8192, settle=0.0)
y = run["xO1"].to_numpy()
y_hat = model.simulate(run["u"].to_numpy(), w, y0=y[:3])
half = len(y) // 2
a = order_components(y[half:], run["phi"].to_numpy()[half:], (1,))[0][0]
a_hat = order_components(y_hat[half:], run["phi"].to_numpy()[half:], (1,))[0][0]
print(f"{w} rad/s: free-run NRMSE {100 * nrmse(y, y_hat):.2f} %, "
      f"1x amplitude error {100 * abs(a_hat / a - 1):.2f} %")
assert nrmse(y, y_hat) < 0.05
