"""NARX on the paper's frequency sweep: free run at held-out speeds, sknarx beside its peers.

Run: ``python benchmarks/bench_narx_sweep.py [--summary]`` (writes
``benchmarks/results/bench_narx_sweep.json``).

Training: the paper's 19 speeds, each record from rest (transient included), 16,384
samples at 1 kHz of the disk's x displacement driven by the unbalance force; held out:
the paper's validation speeds 100.5, 138.2 and 213.6 rad/s, also from rest. Every model
has lags 3 and term degree 3 and free-runs each held-out record from its first measured
outputs; the score is the NRMSE of that free run (percent of the record's RMS).

- sknarx, one-step EFOR (the paper's method), 10 terms, cubic speed polynomials;
- sknarx, the same with output-error refinement (per speed, then the speed polynomials);
- sknarx, simulation-error selection and output-error refinement;
- SysIdentPy 0.9 FROLS and fastcan 0.6 (one-step and output-error training): neither
  schedules coefficients on speed, so each gets the speed as a second input (a static
  one for fastcan) over the concatenated records, 20 terms.

Fit time is the median of the wall times (one BLAS thread); peak memory is traced by
``tracemalloc``. A peer gets ``--peer-timeout`` seconds (default 600) for one fit and
its scores, in a process of its own; one that takes longer is reported as such.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import fit_cost, summary_flag, table, write_json  # noqa: E402, I001

import numpy as np  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from sknarx import RotorBearingSimulator, SpeedScheduledNarx  # noqa: E402
from sknarx.reproduce.case import PaperCase  # noqa: E402

N, LAG, DEGREE = 16384, 3, 3


def sweep():
    case = PaperCase()
    sim = RotorBearingSimulator(seed=case.seed)

    def records(speeds):
        df = sim.sweep(speeds, fs=case.fs, n_samples=N, settle=0.0, n_jobs=1, progress=False)
        return [(g["u"].to_numpy(), g[case.output].to_numpy())
                for _, g in df.groupby("speed", sort=True)]

    speeds = np.asarray(case.speeds, dtype=float)
    held = np.asarray(case.validation_speeds, dtype=float)
    return records(speeds), speeds, records(held), held


def nrmse(y_sim, y):
    y_sim = np.asarray(y_sim, dtype=float).ravel()[: len(y)]
    if not np.all(np.isfinite(y_sim)):
        return float("inf")
    return float(100 * np.sqrt(np.mean((y_sim - y) ** 2) / np.mean(y**2)))


def measure(fit, score, repeat):
    model, cost = fit_cost(fit, repeat)
    try:
        scores = score(model)
    except Exception as exc:  # noqa: BLE001 -- a peer's failure is a result
        scores = {"error": f"{type(exc).__name__}: {exc}"[:200]}
    return model, {**cost, "nrmse_percent": scores}


def sknarx_methods(train, speeds, held, held_speeds, repeat):
    base = dict(ny=LAG, nu=LAG, degree=DEGREE, coef_degree=3)
    settings = {
        "sknarx one-step EFOR": dict(esr=0.0, max_terms=10, prune=False),
        "sknarx one-step + output-error": dict(esr=0.0, max_terms=10, prune=False,
                                               refine="output_error"),
        "sknarx simulation-error + output-error": dict(max_terms=20, selection="simulation",
                                                       refine="output_error"),
    }
    out = {}
    for name, kw in settings.items():
        def fit(kw=kw):
            return SpeedScheduledNarx(**base, **kw).fit(train, speeds)

        def score(m):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return {f"{w:g}": nrmse(m.simulate(u, w, y0=y[:LAG], on_divergence="warn"), y)
                        for (u, y), w in zip(held, held_speeds, strict=True)}

        model, entry = measure(fit, score, repeat)
        entry["terms"] = list(model.selected_terms_)
        out[name] = entry
    return out


def _with_speed(records, speeds):
    X = np.vstack([np.column_stack([u, np.full(len(u), w)])
                   for (u, _), w in zip(records, speeds, strict=True)])
    Y = np.concatenate([y for _, y in records])
    return X, Y


def sysidentpy_method(train, speeds, held, held_speeds, repeat):
    try:
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares
    except ImportError:
        return {}
    X, Y = _with_speed(train, speeds)

    def fit():
        m = FROLS(order_selection=False, n_terms=20, ylag=LAG, xlag=[[1, 2, 3], [1]],
                  basis_function=Polynomial(degree=DEGREE), estimator=LeastSquares(),
                  model_type="NARMAX")
        m.fit(X=X, y=Y.reshape(-1, 1))
        return m

    def score(m):
        out = {}
        for (u, y), w in zip(held, held_speeds, strict=True):
            Xh = np.column_stack([u, np.full(len(u), w)])
            out[f"{w:g}"] = nrmse(m.predict(X=Xh, y=y[:LAG].reshape(-1, 1)), y)
        return out

    _, entry = measure(fit, score, 1)
    return {"SysIdentPy 0.9 FROLS (speed as input)": entry}


def fastcan_methods(train, speeds, held, held_speeds, repeat):
    try:
        from fastcan.narx import make_narx
    except ImportError:
        return {}
    X, Y = _with_speed(train, speeds)
    sessions = [len(y) for _, y in train]
    out = {}
    for name, coef_init in (("fastcan 0.6 one-step (speed as input)", None),
                            ("fastcan 0.6 output-error (speed as input)", "one_step_ahead")):
        def fit(coef_init=coef_init):
            m = make_narx(X, Y, n_terms_to_select=20, max_delay=LAG, poly_degree=DEGREE,
                          session_sizes=sessions, static_indices=[1], refine_verbose=0,
                          verbose=0)
            return m.fit(X, Y, coef_init=coef_init, session_sizes=sessions)

        def score(m):
            out = {}
            for (u, y), w in zip(held, held_speeds, strict=True):
                Xh = np.column_stack([u, np.full(len(u), w)])
                out[f"{w:g}"] = nrmse(m.predict(Xh, y_init=y[:LAG]), y)
            return out

        _, entry = measure(fit, score, 1)
        out[name] = entry
    return out


def _peer(name, queue):
    train, speeds, held, held_speeds = sweep()
    with threadpool_limits(limits=1, user_api="blas"):
        fn = sysidentpy_method if name == "sysidentpy" else fastcan_methods
        queue.put(fn(train, speeds, held, held_speeds, 1))


def run_peer(name, timeout):
    """A peer's results, or a note that it did not finish within ``timeout`` s."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_peer, args=(name, queue))
    proc.start()
    try:
        return queue.get(timeout=timeout)
    except Exception:  # noqa: BLE001 -- queue.Empty: the peer ran out of time
        return {f"{name} (speed as input)": {
            "fit_median_s": float("nan"), "fit_times_s": [], "peak_traced_mb": float("nan"),
            "nrmse_percent": {"error": f"did not finish within {timeout:g} s"}}}
    finally:
        proc.terminate()
        proc.join()


def main(argv=None, repeat=3):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    summary_flag(ap)
    ap.add_argument("--peer-timeout", type=float, default=600.0,
                    help="seconds each peer gets (default 600)")
    args = ap.parse_args(argv)
    train, speeds, held, held_speeds = sweep()
    with threadpool_limits(limits=1, user_api="blas"):
        results = sknarx_methods(train, speeds, held, held_speeds, repeat)
    for peer in ("sysidentpy", "fastcan"):
        results.update(run_peer(peer, args.peer_timeout))
    rows = []
    for name, r in results.items():
        s = r["nrmse_percent"]
        cells = ([f"{s.get(f'{w:g}', float('nan')):.3f}" for w in held_speeds]
                 if "error" not in s else ["failed", s["error"][:40], ""])
        rows.append([name, *cells, f"{r['fit_median_s']:.2f}", f"{r['peak_traced_mb']:.0f}"])
    table(rows, ["method", *[f"NRMSE % at {w:g} rad/s" for w in held_speeds], "fit (s)",
                 "peak (MB)"])
    write_json("bench_narx_sweep", {
        "setup": {"samples_per_record": N, "lags": LAG, "degree": DEGREE,
                  "training_speeds_rad_s": speeds.tolist(),
                  "held_out_speeds_rad_s": held_speeds.tolist()},
        "methods": results}, args.summary)
    return results


if __name__ == "__main__":
    main()
