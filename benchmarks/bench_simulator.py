"""Simulator speed and accuracy, side by side with scipy's solve_ivp.

Run: ``python benchmarks/bench_simulator.py [--summary]`` (writes
``benchmarks/results/bench_simulator.json``).

1. One speed (250 rad/s, 2 s from the static equilibrium, sampled at 1 kHz):
   sknarx's compiled RK4 at its default step against ``solve_ivp`` RK45
   (rtol 1e-6) with a vectorised-NumPy right-hand side of the same equations.
   Both are scored against a DOP853 rtol 1e-10 reference on the 1x and 2x
   amplitudes of disk O1 over the last second, so the speed ratio is at equal
   (or better) accuracy. Target: >= 50x.
2. The paper's sweep: 19 speeds x 81,921 samples at 1 kHz plus 2 s of settling,
   on this machine's cores. Target: <= 10 s.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import summary_flag, table, timeit, write_json  # noqa: E402, I001

import numpy as np  # noqa: E402

import sknarx.rotor as R  # noqa: E402
from sknarx.orders import order_components  # noqa: E402
from sknarx.rotor.reference import solve_reference  # noqa: E402

W, T, FS = 250.0, 2.0, 1000.0  # rad/s, s, Hz


def amplitudes(x, phi):
    half = slice(len(x) // 2, None)
    return order_components(x[half], phi[half], (1, 2))[0]


def main(argv=None, repeat=3):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    summary_flag(ap)
    args = ap.parse_args(argv)
    sim = R.RotorBearingSimulator()
    n = int(T * FS) + 1
    phi = W * np.arange(n) / FS
    i = R.DOF_NAMES.index("xO1")

    t0 = time.perf_counter()
    sim.simulate(W, fs=FS, n_samples=10, settle=0.0)
    compile_s = time.perf_counter() - t0
    sim.static_equilibrium()

    ref, _ = solve_reference(sim, W, T, FS, method="DOP853", rtol=1e-10)
    a_ref = amplitudes(ref[:, i], phi)
    t_ours, ours_times, run = timeit(
        lambda: sim.simulate(W, fs=FS, n_samples=n, settle=0.0), repeat)
    a_ours = amplitudes(run["xO1"].to_numpy(), run["phi"].to_numpy())
    t_ivp, ivp_times, (y_ivp, sol) = timeit(
        lambda: solve_reference(sim, W, T, FS, method="RK45", rtol=1e-6), max(1, repeat - 1))
    a_ivp = amplitudes(y_ivp[:, i], phi)
    err_ours = np.abs(a_ours / a_ref - 1)
    err_ivp = np.abs(a_ivp / a_ref - 1)

    # equal accuracy: refine our step until both amplitude errors are <= solve_ivp's
    matched = None
    for factor in (2.0, 1.0, 0.5, 0.25, 0.125):
        fine = R.RotorBearingSimulator(step_factor=factor)
        t_f, f_times, run_f = timeit(
            lambda fine=fine: fine.simulate(W, fs=FS, n_samples=n, settle=0.0), repeat)
        err_f = np.abs(amplitudes(run_f["xO1"].to_numpy(), run_f["phi"].to_numpy()) / a_ref - 1)
        if np.all(err_f <= err_ivp):
            matched = {"step_factor": factor, "substeps": fine.substeps(FS, W),
                       "median_s": t_f, "times_s": f_times, "rel_error_1x_2x": err_f.tolist(),
                       "speedup_at_equal_accuracy": t_ivp / t_f}
            break

    speeds = np.linspace(81.7, 276.5, 19)
    n_jobs = os.cpu_count() or 1
    sim.sweep(speeds[:2], fs=FS, n_samples=100, settle=0.1, n_jobs=n_jobs, progress=False)
    t_sweep, sweep_times, df = timeit(
        lambda: sim.sweep(speeds, fs=FS, n_samples=81921, settle=2.0, n_jobs=n_jobs,
                          progress=False), repeat)

    results = {
        "one_speed": {
            "speed_rad_s": W, "duration_s": T, "fs_hz": FS,
            "substeps": sim.substeps(FS, W),
            "sknarx_median_s": t_ours, "sknarx_times_s": ours_times,
            "solve_ivp_rk45_median_s": t_ivp, "solve_ivp_times_s": ivp_times,
            "solve_ivp_nfev": int(sol.nfev),
            "speedup": t_ivp / t_ours, "target_speedup": 50,
            "rel_error_1x_2x_sknarx": err_ours.tolist(),
            "rel_error_1x_2x_solve_ivp": err_ivp.tolist(),
            "compile_s_first_call": compile_s,
            "equal_accuracy": matched,
        },
        "paper_sweep": {
            "speeds": 19, "n_samples": 81921, "fs_hz": FS, "settle_s": 2.0, "n_jobs": n_jobs,
            "median_s": t_sweep, "times_s": sweep_times, "rows": len(df), "target_s": 10.0,
        },
    }
    one = results["one_speed"]
    table(
        [
            ["one speed, 2 s", f"{t_ours * 1e3:.1f} ms", f"{t_ivp:.2f} s (RK45 1e-6)",
             f"{one['speedup']:.0f}x faster", ">= 50x"],
            ["  1x / 2x amplitude error", f"{err_ours[0]:.1e} / {err_ours[1]:.1e}",
             f"{err_ivp[0]:.1e} / {err_ivp[1]:.1e}", "", "equal accuracy"],
            ["at equal accuracy (step_factor "
             f"{matched['step_factor'] if matched else '-'})",
             f"{matched['median_s'] * 1e3:.1f} ms" if matched else "not reached",
             f"{t_ivp:.2f} s",
             f"{matched['speedup_at_equal_accuracy']:.0f}x faster" if matched else "", ">= 50x"],
            ["paper sweep 19 x 81,921", f"{t_sweep:.2f} s", "", "", "<= 10 s"],
            ["first-call compile", f"{compile_s:.1f} s", "", "", "(not timed above)"],
        ],
        ["case", "sknarx", "peer", "ratio", "target"],
    )
    write_json("bench_simulator", results, args.summary)
    return results


if __name__ == "__main__":
    main()
