"""NARX on real data: the Silverbox benchmark, sknarx side by side with its peers.

Run: ``python benchmarks/bench_narx_silverbox.py [--summary]`` (writes
``benchmarks/results/bench_narx_silverbox.json``).

Every method fits on the ten multisine realisations (each a record: its 460 transient
samples are lag history), with lags 4 and term degree 3, and free-runs the test arrow
from its first measured outputs; the error is quoted in mV after the first 100 samples,
on the full arrow (file rows 100-40,099) and within the estimation range (rows
100-30,099). Methods:

- sknarx, one-step FROLS (the paper's selection), 10 terms;
- sknarx, simulation-error selection (``selection='simulation'``);
- sknarx, simulation-error selection and output-error refinement (the recommended);
- SysIdentPy 0.9 FROLS, 10 terms, on the concatenated realisations (it takes one record);
- fastcan 0.6 ``make_narx`` (10 terms, its records as sessions) and its NARX fitted on
  the free-run error from the one-step coefficients (``coef_init='one_step_ahead'``).

Fit time is the median of the wall times (one BLAS thread); peak memory is traced by
``tracemalloc`` (numpy reports its buffers there).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import fit_cost, summary_flag, table, write_json  # noqa: E402, I001

import numpy as np  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from sknarx import SpeedScheduledNarx  # noqa: E402
from sknarx.datasets import load_silverbox  # noqa: E402

LAG, DEGREE, TERMS = 4, 3, 10


def _rmse_mv(y_sim, y):
    e = 1e3 * (np.asarray(y_sim, dtype=float) - y)
    if not np.all(np.isfinite(e[100:40100])):
        return float("nan"), float("nan")
    return (float(np.sqrt(np.mean(e[100:40100] ** 2))),
            float(np.sqrt(np.mean(e[100:30100] ** 2))))


def _measure(fit, simulate, repeat):
    model, cost = fit_cost(fit, repeat)
    try:
        full, within = _rmse_mv(*simulate(model))
        diverged = not np.isfinite(full)
    except Exception as exc:  # noqa: BLE001 -- a peer's failure is a result
        full = within = float("nan")
        diverged = f"{type(exc).__name__}: {exc}"[:200]
    return model, {**cost, "rmse_full_arrow_mV": full, "rmse_within_range_mV": within,
                   "diverged": diverged}


def sknarx_methods(records, u, y, repeat):
    out = {}
    settings = {
        "sknarx one-step FROLS": dict(max_terms=TERMS, esr=0.0, prune=False),
        "sknarx simulation-error selection": dict(max_terms=20, selection="simulation"),
        "sknarx simulation-error + output-error": dict(max_terms=20, selection="simulation",
                                                       refine="output_error"),
    }
    for name, kw in settings.items():
        def fit(kw=kw):
            return SpeedScheduledNarx(ny=LAG, nu=LAG, degree=DEGREE, **kw).fit(records)

        def simulate(m):
            return m.simulate(u, y0=y[:LAG], on_divergence="warn"), y

        model, entry = _measure(fit, simulate, repeat)
        entry["terms"] = list(model.selected_terms_)
        out[name] = entry
    return out


def sysidentpy_method(records, u, y, repeat):
    try:
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares
    except ImportError:
        return {"available": False}
    uc = np.concatenate([r[0] for r in records]).reshape(-1, 1)
    yc = np.concatenate([r[1] for r in records]).reshape(-1, 1)

    def fit():
        m = FROLS(order_selection=False, n_terms=TERMS, ylag=LAG, xlag=LAG,
                  basis_function=Polynomial(degree=DEGREE), estimator=LeastSquares(),
                  model_type="NARMAX")
        m.fit(X=uc, y=yc)
        return m

    def simulate(m):
        y_sim = m.predict(X=u.reshape(-1, 1), y=y[:LAG].reshape(-1, 1), steps_ahead=None)
        return np.asarray(y_sim).ravel()[: len(y)], y

    _, entry = _measure(fit, simulate, max(1, repeat // 2))
    return {"SysIdentPy 0.9 FROLS": entry}


def fastcan_methods(records, u, y, repeat):
    try:
        from fastcan.narx import make_narx
    except ImportError:
        return {}
    X = np.concatenate([r[0] for r in records]).reshape(-1, 1)
    Y = np.concatenate([r[1] for r in records])
    sessions = [len(r[1]) for r in records]
    out = {}
    for name, coef_init in (("fastcan 0.6 one-step", None),
                            ("fastcan 0.6 output-error", "one_step_ahead")):
        def fit(coef_init=coef_init):
            m = make_narx(X, Y, n_terms_to_select=TERMS, max_delay=LAG, poly_degree=DEGREE,
                          session_sizes=sessions, refine_verbose=0)
            return m.fit(X, Y, coef_init=coef_init, session_sizes=sessions)

        def simulate(m):
            return m.predict(u.reshape(-1, 1), y_init=y[:LAG]), y

        _, entry = _measure(fit, simulate, max(1, repeat // 2))
        out[name] = entry
    return out


def main(argv=None, repeat=3):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    summary_flag(ap)
    args = ap.parse_args(argv)
    data = load_silverbox()
    records = [(r.V1.to_numpy(), r.V2.to_numpy()) for r in data.estimation]
    u, y = data.frame.V1.to_numpy()[:40500], data.frame.V2.to_numpy()[:40500]
    with threadpool_limits(limits=1, user_api="blas"):
        results = sknarx_methods(records, u, y, repeat)
        results.update(sysidentpy_method(records, u, y, repeat))
        results.update(fastcan_methods(records, u, y, repeat))
    rows = []
    for name, r in results.items():
        if not isinstance(r, dict) or "fit_median_s" not in r:
            continue
        rows.append([name, f"{r['rmse_full_arrow_mV']:.3f}", f"{r['rmse_within_range_mV']:.3f}",
                     len(r.get("terms", [])) or TERMS, f"{r['fit_median_s']:.2f}",
                     f"{r['peak_traced_mb']:.0f}", r["diverged"] or ""])
    table(rows, ["method", "full arrow (mV)", "within range (mV)", "terms", "fit (s)",
                 "peak (MB)", "diverged"])
    write_json("bench_narx_silverbox", {
        "setup": {"lags": LAG, "degree": DEGREE, "terms_fixed": TERMS,
                  "targets_mV": {"full_arrow": 1.0, "within_range": 0.6}},
        "methods": results}, args.summary)
    return results


if __name__ == "__main__":
    main()
