"""A two-output x/y model at disk O1 against two single-output models, at unseen speeds.

Run: ``python -m validation.narx_two_outputs [OUT.json]``

Training: the paper's 19 speeds, each record from rest, 16,384 samples at 1 kHz; the
inputs are the unbalance force's x and y components (N), the outputs xO1 and yO1 (m).
Held out: the paper's validation speeds (100.5, 138.2, 213.6 rad/s), also from rest.
Every model free-runs each held-out record from its first measured outputs; the score
is the NRMSE of that run (percent of the output's standard deviation).

- two single-output models (x from the x force, y from the y force), lags 3, degree 3
  and degree 2, 10 terms, one-step selection and output-error refinement;
- the two-output model over both outputs' and both inputs' lags, degree 2, 10 terms
  per output, the same selection and refinement.
"""

from __future__ import annotations

import json
import sys
import warnings

import numpy as np

from sknarx import MultiOutputScheduledNarx, RotorBearingSimulator, SpeedScheduledNarx
from sknarx.reproduce.case import PaperCase

N = 16384


def forces(run):
    """The unbalance force's components: ``u`` is its x component, ``a cos(phi) +
    b sin(phi)``; the y component is the same rotating vector a quarter turn on."""
    u, phi = run["u"].to_numpy(), run["phi"].to_numpy()
    a, b = np.linalg.lstsq(np.column_stack([np.cos(phi), np.sin(phi)]), u, rcond=None)[0]
    return np.column_stack([u, a * np.sin(phi) - b * np.cos(phi)])


def records(sim, speeds):
    df = sim.sweep(speeds, fs=1000.0, n_samples=N, settle=0.0, n_jobs=None, progress=False)
    return [(forces(g), g[["xO1", "yO1"]].to_numpy()) for _, g in df.groupby("speed",
                                                                               sort=True)]


def nrmse(y_sim, y):
    if not np.all(np.isfinite(y_sim)):
        return float("inf")
    return float(100 * np.sqrt(np.mean((y_sim - y) ** 2)) / np.std(y))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    case = PaperCase()
    sim = RotorBearingSimulator(seed=case.seed)
    speeds = np.asarray(case.speeds, dtype=float)
    held = np.asarray(case.validation_speeds, dtype=float)
    train, test = records(sim, speeds), records(sim, held)
    kw = dict(ny=3, nu=3, max_terms=10, esr=0.0, prune=False, coef_degree=3,
              refine="output_error")
    results = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for degree in (3, 2):
            single = [SpeedScheduledNarx(degree=degree, **kw).fit(
                [(U[:, c], Y[:, c]) for U, Y in train], speeds) for c in (0, 1)]
            results[f"two single-output, degree {degree}"] = {
                f"{w:g}": [nrmse(m.simulate(U[:, c], w, y0=Y[:3, c], on_divergence="warn"),
                                 Y[:, c]) for c, m in enumerate(single)]
                for (U, Y), w in zip(test, held, strict=True)}
        joint = MultiOutputScheduledNarx(degree=2, **kw).fit(train, speeds)
        results["two-output, degree 2"] = {
            f"{w:g}": [nrmse(Ys[:, c], Y[:, c]) for c in (0, 1)]
            for (U, Y), w in zip(test, held, strict=True)
            for Ys in [joint.simulate(U, w, Y0=Y[:3], on_divergence="warn")]}
    print(f"{'model':34s}" + "".join(f"{w:>8g} rad/s x, y (%)   " for w in held))
    for name, r in results.items():
        print(f"{name:34s}" + "".join(f"{r[f'{w:g}'][0]:12.4f} {r[f'{w:g}'][1]:8.4f}   "
                                      for w in held))
    if argv:
        with open(argv[0], "w") as f:
            json.dump({"nrmse_percent_x_y": results, "terms": joint.selected_terms_}, f,
                      indent=1)
    return results


if __name__ == "__main__":
    main()
