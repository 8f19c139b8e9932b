"""Cost of trusting a model, and NARMAX side by side with SysIdentPy's extended least squares.

Run: ``python benchmarks/bench_narx_uncertainty.py`` (writes
``benchmarks/results/bench_narx_uncertainty.json``; about 3 minutes).

1. The paper's sweep (19 speeds x 81,921 samples from rest, the simulator's disk O1 x;
   ny = nu = 3, degree 3, ten terms, spline speed basis, the reproduction's settings):
   ``fit`` with its uncertainty (per-speed covariances, propagated speed-function
   errors) against the same ``fit`` with the covariance kernel replaced by a stub, and
   the five correlation tests on the same records, all in one run. Target: uncertainty
   plus validity tests add at most 20 % to ``fit``.
2. ARMAX data ``y = 0.5 y(t-1) + u(t-1) + e(t) + 0.8 e(t-1)`` (N = 3,000, 50 draws):
   bias, RMSE and the coverage of 95 % intervals of ``a = 0.5`` for NARX least squares,
   sknarx NARMAX (``noise_lags=2``) and SysIdentPy's FROLS with
   ``LeastSquares(unbiased=True)`` (its ELS, ``elag=2``), and their fit times.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
from _common import summary_flag, table, timeit, write_json  # noqa: E402

import sknarx.narx.scheduling as scheduling  # noqa: E402
from sknarx import SpeedScheduledNarx  # noqa: E402
from sknarx.narx.validity import correlation_tests  # noqa: E402
from sknarx.reproduce import PaperCase  # noqa: E402
from sknarx.rotor import RotorBearingSimulator  # noqa: E402


def paper_sweep():
    case = PaperCase()
    sim = RotorBearingSimulator(seed=case.seed)
    speeds = np.asarray(case.speeds)
    rest = sim.sweep(speeds, fs=case.fs, n_samples=case.n_samples, settle=0.0,
                     n_jobs=case.n_jobs, progress=False)
    data = [(g["u"].to_numpy(), g[case.output].to_numpy())
            for _, g in rest.groupby("speed", sort=True)]
    params = dict(ny=case.ny, nu=case.nu, degree=case.degree, esr=case.esr,
                  max_terms=case.max_terms, coef_degree=case.coef_degree, prune=False,
                  speed_basis="spline")
    return data, speeds, params


def _stub_covariance(res, norms, n_rows):
    K, s = len(n_rows), len(res.selected)
    return np.zeros((K, s, s)), np.zeros(K), np.asarray(n_rows, dtype=float) - s


def overhead(repeat):
    data, speeds, params = paper_sweep()

    def fit():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return SpeedScheduledNarx(**params).fit(data, speeds)

    real = scheduling.coef_covariance
    scheduling.coef_covariance = _stub_covariance
    try:
        t_without, times_without, _ = timeit(fit, repeat)
    finally:
        scheduling.coef_covariance = real
    t_with, times_with, model = timeit(fit, repeat)
    t_tests, times_tests, tests = timeit(lambda: correlation_tests(model, data, speeds),
                                         repeat)
    added = (t_with + t_tests) / t_without - 1.0
    rows = [["fit, covariance stubbed out", f"{t_without:.2f}"],
            ["fit with uncertainty", f"{t_with:.2f}"],
            ["correlation tests (5 tests, 20 lags, 19 records)", f"{t_tests:.2f}"],
            ["added by uncertainty + tests", f"{100 * added:+.1f} % (target <= +20 %)"]]
    print("\n1. Paper sweep: 19 x 81,921 samples, 84 candidates, 10 terms (median of "
          f"{repeat})")
    table(rows, ["step", "seconds"])
    return {"fit_without_uncertainty_s": times_without, "fit_with_uncertainty_s": times_with,
            "correlation_tests_s": times_tests, "median_fit_without_s": t_without,
            "median_fit_with_s": t_with, "median_tests_s": t_tests,
            "added_fraction": added, "target_added_fraction": 0.20,
            "meets_target": bool(added <= 0.20), "n_rows_tests": int(len(tests))}


def armax(seed, n=3000, a=0.5, c=0.8):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    e = 0.3 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = a * y[t - 1] + u[t - 1] + e[t] + c * e[t - 1]
    return u, y


def narmax_side_by_side(draws):
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    est = {"NARX least squares": [], "sknarx NARMAX (ELS + PEM)": [],
           "SysIdentPy FROLS unbiased (ELS)": []}
    times = {k: [] for k in est}
    cover = {"NARX least squares": 0, "sknarx NARMAX (ELS + PEM)": 0}
    import time

    for seed in range(draws):
        u, y = armax(seed)
        for name, noise in (("NARX least squares", 0), ("sknarx NARMAX (ELS + PEM)", 2)):
            t = time.perf_counter()
            m = SpeedScheduledNarx(ny=1, nu=1, degree=1, max_terms=2, esr=0, coef_degree=0,
                                   noise_lags=noise).fit([(u, y)], [1.0])
            times[name].append(time.perf_counter() - t)
            a = float(m.coef_per_speed_["y(t-1)"].iloc[0])
            se = float(m.coef_std_err_per_speed_["y(t-1)"].iloc[0])
            est[name].append(a)
            cover[name] += abs(a - 0.5) <= 1.96 * se
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = time.perf_counter()
            sid = FROLS(order_selection=False, n_terms=2, ylag=1, xlag=1, elag=2,
                        estimator=LeastSquares(unbiased=True),
                        basis_function=Polynomial(degree=1),
                        model_type="NARMAX").fit(X=u[:, None], y=y[:, None])
            times["SysIdentPy FROLS unbiased (ELS)"].append(time.perf_counter() - t)
        codes = [r[0] for r in sid.final_model]
        est["SysIdentPy FROLS unbiased (ELS)"].append(float(np.ravel(sid.theta)[codes.index(1001)]))
    rows, out = [], {}
    for name, values in est.items():
        v = np.asarray(values)
        out[name] = {"bias": float(v.mean() - 0.5), "rmse": float(np.sqrt(np.mean((v - 0.5) ** 2))),
                     "median_fit_s": float(np.median(times[name])),
                     "coverage_95": (cover[name] / draws) if name in cover else None}
        rows.append([name, f"{out[name]['bias']:+.4f}", f"{out[name]['rmse']:.4f}",
                     "-" if name not in cover else f"{100 * cover[name] / draws:.0f} %",
                     f"{1e3 * out[name]['median_fit_s']:.1f}"])
    print(f"\n2. ARMAX, a = 0.5, MA(1) c = 0.8, N = 3,000, {draws} draws")
    table(rows, ["estimator", "bias of a", "RMSE of a", "95 % CI coverage", "fit (ms, median)"])
    return out


def main():
    import argparse

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--draws", type=int, default=50)
    summary_flag(p)
    args = p.parse_args()
    payload = {"overhead": overhead(args.repeat), "narmax": narmax_side_by_side(args.draws)}
    write_json("bench_narx_uncertainty", payload, args.summary)


if __name__ == "__main__":
    main()
