"""Judge an identified model: standard errors, residual correlation tests, a noise model.

A speed-scheduled system with coloured (moving-average) equation noise, as on a real
rig: NARX least squares is biased and its residuals fail the phi_ee test; NARMAX
(``noise_lags``) passes every test and its coefficients cover the truth.

Run: python examples/05_judging_a_model.py
"""

import numpy as np

from sknarx import SpeedScheduledNarx
from sknarx.narx.validity import correlation_tests, validity_summary

rng = np.random.default_rng(0)
speeds = np.array([100.0, 150.0, 200.0, 250.0])  # rad/s
data = []
for w in speeds:
    u = rng.uniform(-1, 1, 3000)
    e = 0.1 * rng.standard_normal(3000)
    y = np.zeros(3000)
    for t in range(1, 3000):  # true a(w) = 0.3 + 1e-3 w; noise e(t) + 0.8 e(t-1)
        y[t] = ((0.3 + 1e-3 * w) * y[t - 1] + u[t - 1] + 0.4 * u[t - 1] ** 2
                + e[t] + 0.8 * e[t - 1])
    data.append((u, y))

settings = dict(ny=1, nu=1, degree=2, max_terms=3, esr=0, coef_degree=1)
for label, model in (("NARX", SpeedScheduledNarx(**settings)),
                     ("NARMAX", SpeedScheduledNarx(**settings, noise_lags=2))):
    model.fit(data, speeds)
    table = model.summary()  # one row per speed and term: coef, std_err, t_value, ERR, AERR
    a = table[table.term == "y(t-1)"]
    z = (a.coef - (0.3 + 1e-3 * a.speed)) / a.std_err
    verdict = validity_summary(correlation_tests(model, data, speeds))
    pooled = verdict[verdict.scope == "pooled"].set_index("test")
    print(f"{label}: terms {model.selected_terms_}")
    print(f"  y(t-1) error in standard errors at each speed: {np.round(z.to_numpy(), 1)}")
    print("  correlation tests (pooled): "
          + ", ".join(f"{t} {'pass' if ok else 'FAIL'}" for t, ok in pooled.passed.items()))

print(model.summary(kind="speed_function").round(5).to_string(index=False))
band = model.simulate_interval(data[0][0][:500], 175.0, n_draws=200, random_state=0)
width = np.mean(band.upper - band.lower)
print(f"free run at 175 rad/s: mean 95 % band width {width:.4f}, "
      f"{100 * band.diverged_fraction:.0f} % of the draws diverged")
assert pooled.passed.all()
