"""The two-pass test on a real rotor that did not change: repeated records of the RK-4 rig.

Run: ``python benchmarks/bench_gap_passes_real.py`` (a few seconds; writes
``results/bench_gap_passes_real.json``).

Every validation of the pass test so far compared simulated passes, whose records differ
by their noise and keyphasor jitter alone. A real rig does not repeat that well: its
temperature, speed control and probe electronics drift between records. The shipped RK-4
unbalance campaign (``sknarx.datasets.load_rk4_unbalance``: Bently Nevada RK-4, four
proximity probes, 1x vectors in mils 0-peak, runout-compensated) recorded every mounted
condition three times at each of two dwell speeds without touching the rotor in between.
Any two of those acquisitions are two passes of an unchanged rotor (two steps, four
probes). Here each pair is compared by :func:`sknarx.gap.passes.compare_pass_features`,
the kernel ``compare_passes`` runs once it has the passes' features: the reference's
common offset removed per step (at most 5 degrees), the dead band ``pass_rtol`` (and a
moved step's slope), and the statistic against the frozen floor.

What the file does not hold is each record's standard error: the source kept the 1x
vectors, not the records. The noise is therefore estimated from the repeats themselves.
Per probe, the squared difference of two acquisitions is regressed on the squared size
of the vector (least squares over every pair): the intercept is twice one record's noise
variance (per vector, two components), and the slope is the squared relative difference
beyond the noise. The noise used for every probe is the largest of the four probes'
(the probes and their electronics are of one type; the largest keeps the test least
sensitive), scaled by ``--noise-scales`` to show how the answer depends on it.

The question: how many pairs of an unchanged real rotor's records does the test call
changed, at each ``pass_rtol``? At the package's floor a test whose null holds flags
about one in a hundred.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from _common import table, write_json  # noqa: E402

from sknarx.datasets import load_rk4_unbalance  # noqa: E402
from sknarx.gap import DiagnosisSettings  # noqa: E402
from sknarx.gap.passes import compare_pass_features  # noqa: E402

PROBES = ("plane1_x", "plane1_y", "plane2_x", "plane2_y")
#: the reference's common offset the comparison removes per step, at most (degrees)
MAX_OFFSET_DEG = 5.0


def repeated_pairs(frame):
    """Every pair of acquisitions of one mounted condition, as ``(condition, a, b,
    first, second)`` with each side's rows sorted by dwell speed; a pair whose sides hold
    different dwells is left out."""
    out = []
    for cond, g in frame.groupby("condition_id", sort=True):
        for a, b in itertools.combinations(sorted(g["acq_idx"].unique()), 2):
            first = g[g["acq_idx"] == a].sort_values("speed_id")
            second = g[g["acq_idx"] == b].sort_values("speed_id")
            if list(first["speed_id"]) == list(second["speed_id"]):
                out.append((cond, int(a), int(b), first, second))
    return out


def vectors(rows):
    """The rows' 1x vectors (mil), shaped records x probes, complex."""
    return np.stack([rows[f"{p}_1x_re"].to_numpy() + 1j * rows[f"{p}_1x_im"].to_numpy()
                     for p in PROBES], axis=1)


def aligned_difference(a, b):
    """``a - b`` per step after the common phase offset between them (over the probes,
    at most :data:`MAX_OFFSET_DEG`) is removed, and the mean size ``|a + b| / 2``."""
    lim = np.radians(MAX_OFFSET_DEG)
    delta = np.clip(np.angle(np.sum(a * np.conj(b), axis=1, keepdims=True)), -lim, lim)
    return np.abs(a * np.exp(-1j * delta) - b), np.abs(a + b) / 2.0


def repeatability(pairs):
    """Per probe, the least-squares fit of ``|a - b|^2 = c0 + c1 |x|^2`` over every
    step of every pair: one record's noise (per component, ``sqrt(c0 / 4)``, mil) and the
    relative difference beyond it (``sqrt(c1)``)."""
    d, x = [], []
    for *_, first, second in pairs:
        dd, xx = aligned_difference(vectors(first), vectors(second))
        d.append(dd)
        x.append(xx)
    d, x = np.concatenate(d), np.concatenate(x)
    out = {}
    for k, p in enumerate(PROBES):
        design = np.column_stack([np.ones(len(x)), x[:, k] ** 2])
        (c0, c1), *_ = np.linalg.lstsq(design, d[:, k] ** 2, rcond=None)
        out[p] = {"noise_mil": float(np.sqrt(max(c0, 0.0) / 4.0)),
                  "relative": float(np.sqrt(max(c1, 0.0))),
                  "median_size_mil": float(np.median(x[:, k]))}
    return out


def features(rows, se_mil):
    """One side of a pair as the gap map's feature table (speed in rad/s, sizes in
    mil: the comparison is in ratios, so the unit is the data's own)."""
    z = vectors(rows)
    speed = rows["rpm_measured"].to_numpy(dtype=float) * 2.0 * np.pi / 60.0
    return pd.DataFrame([{"speed": w, "window": "steady", "channel": p, "feature": "1x",
                          "re": z[i, k].real, "im": z[i, k].imag, "se": se_mil}
                         for i, w in enumerate(speed) for k, p in enumerate(PROBES)])


def statistic(first, second, se_mil, rtol):
    """The pass test's statistic for one pair (a normal deviate; over the floor: called
    changed), by :func:`sknarx.gap.passes.compare_pass_features` with the dead band
    ``rtol``."""
    settings = replace(DiagnosisSettings(), pass_rtol=rtol)
    return compare_pass_features(features(first, se_mil), features(second, se_mil),
                                 settings).statistic


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rtols", default="0.003,0.01,0.02,0.03,0.05",
                    help="the pass_rtol values to compare with, comma-separated")
    ap.add_argument("--noise-scales", default="0.5,1,2",
                    help="factors on the estimated noise, comma-separated")
    args = ap.parse_args(argv)
    try:
        rtols = [float(v) for v in args.rtols.split(",")]
        scales = [float(v) for v in args.noise_scales.split(",")]
    except ValueError:
        ap.error("--rtols and --noise-scales take comma-separated numbers")
    floor = DiagnosisSettings().pass_floor_sigmas
    pairs = repeated_pairs(load_rk4_unbalance().frame)
    rep = repeatability(pairs)
    table([[p, f"{v['noise_mil']:.5f}", f"{100 * v['relative']:.2f} %",
            f"{v['median_size_mil']:.3f}"] for p, v in rep.items()],
          ["probe", "one record's noise (mil, per component)",
           "relative difference beyond it", "median 1x (mil)"])
    se = max(v["noise_mil"] for v in rep.values())
    print(f"\n{len(pairs)} pairs of repeated acquisitions; noise used for every probe: "
          f"{se:.5f} mil (the largest), times each scale\n")
    rows, grid = [], []
    for scale in scales:
        for rtol in rtols:
            stats = np.array([statistic(f, s, scale * se, rtol) for *_, f, s in pairs])
            over = int(np.sum(stats > floor))
            grid.append({"noise_scale": scale, "pass_rtol": rtol, "n_pairs": len(stats),
                         "n_over_floor": over, "median": float(np.median(stats)),
                         "p99": float(np.percentile(stats, 99)), "max": float(stats.max())})
            rows.append([f"x{scale:g}", f"{rtol:g}", f"{over}/{len(stats)}",
                         f"{np.median(stats):.2f}", f"{np.percentile(stats, 99):.2f}",
                         f"{stats.max():.2f}"])
    table(rows, ["noise", "pass_rtol", "pairs called changed", "median", "99 %", "largest"])
    # by how far apart the two acquisitions are (their order in the campaign)
    package = DiagnosisSettings().pass_rtol
    by_gap = {}
    for _, a, b, f, s in pairs:
        got = by_gap.setdefault(f"{a}-{b}", [0, 0])
        got[0] += statistic(f, s, se, package) > floor
        got[1] += 1
    print("\nat the package's pass_rtol, by acquisitions compared: " + ", ".join(
        f"{k}: {v[0]}/{v[1]}" for k, v in sorted(by_gap.items())))
    largest = sorted(((statistic(f, s, se, package), cond, a, b)
                      for cond, a, b, f, s in pairs), reverse=True)[:5]
    print("largest: " + ", ".join(f"{c} {a}-{b} {v:.1f}" for v, c, a, b in largest))
    write_json("bench_gap_passes_real", {
        "command": "python benchmarks/bench_gap_passes_real.py " + " ".join(
            argv if argv is not None else sys.argv[1:]),
        "data": "sknarx.datasets.load_rk4_unbalance (RK-4, 1x in mil 0-peak)",
        "floor_sigmas": floor, "repeatability": rep, "noise_used_mil": se,
        "grid": grid, "by_acquisitions": by_gap,
        "largest": [{"condition": c, "acquisitions": [a, b], "statistic": v}
                    for v, c, a, b in largest]})


if __name__ == "__main__":
    main()
