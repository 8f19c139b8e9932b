"""A NARX model of the Silverbox circuit, the standard real nonlinear benchmark.

Run: python examples/silverbox.py OUT

Fits on the ten multisine realisations (each its own record: the 460 transient samples
give the lag history), with the terms chosen by free-run error and the coefficients
refined on it, then free-runs the test arrow from its first measured outputs. Writes
``OUT/model.json`` (the estimator's JSON), ``OUT/metrics.json`` and
``OUT/freerun_error.png``, and prints the free-run RMSE in mV after the first 100
samples of the arrow: on the full arrow (rows 100-40,099 of the file) and within the
estimation data's amplitude range (rows 100-30,099). About ten seconds on two cores.
"""

import json
import sys
from pathlib import Path

import numpy as np

from sknarx import SpeedScheduledNarx
from sknarx.datasets import load_silverbox
from sknarx.plotting import plt, save

out = Path(sys.argv[1] if len(sys.argv) > 1 else "silverbox-out")
out.mkdir(parents=True, exist_ok=True)

data = load_silverbox()
records = [(r.V1.to_numpy(), r.V2.to_numpy()) for r in data.estimation]
model = SpeedScheduledNarx(ny=4, nu=4, degree=3, max_terms=20, selection="simulation",
                           refine="output_error")
model.fit(records)  # no speeds: one operating point, one set of coefficients
model.to_json(out / "model.json")

# the arrow is rows 100-40,499 of the file; rows 0-99 (the circuit at rest) start the run
u, y = data.frame.V1.to_numpy()[:40500], data.frame.V2.to_numpy()[:40500]
lag = max(model.ny_, model.nu_)
y_sim = model.simulate(u, y0=y[:lag])
error_mv = 1e3 * (y_sim - y)
full = float(np.sqrt(np.mean(error_mv[100:40100] ** 2)))
within = float(np.sqrt(np.mean(error_mv[100:30100] ** 2)))
metrics = {
    "rmse_full_arrow_mV": full,
    "rmse_within_range_mV": within,
    "rows_full_arrow": [100, 40099],
    "rows_within_range": [100, 30099],
    "terms": model.selected_terms_,
    "settings": {k: v for k, v in model.get_params().items()},
}
(out / "metrics.json").write_text(json.dumps(metrics, indent=1))

t = np.arange(100, 40100)
fig, ax = plt.subplots(figsize=(8, 3.2))
ax.plot(t, error_mv[100:40100], lw=0.3, color="C3")
ax.axvline(30100, color="0.4", ls="--", lw=0.8)
ax.annotate("beyond the estimation range", (30100, 0.9), xycoords=("data", "axes fraction"),
            xytext=(6, 0), textcoords="offset points", fontsize=7)
ax.set(xlabel="sample of the file", ylabel="free run - measured (mV)",
       title=f"Silverbox test arrow: free-run error, RMSE {full:.2f} mV "
             f"({within:.2f} mV within range)")
save(fig, out / "freerun_error.png")

print(f"{len(model.selected_terms_)} terms: {', '.join(model.selected_terms_)}")
print(f"free-run RMSE, full arrow:   {full:.3f} mV")
print(f"free-run RMSE, within range: {within:.3f} mV")
