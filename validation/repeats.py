"""The two-pass test on a real rotor that did not change: the RK-4 rig's repeats.

Run: ``python -m validation.repeats`` (seconds). The shipped RK-4 unbalance campaign
(:func:`sknarx.datasets.load_rk4_unbalance`: four proximity probes, 1x vectors in mil,
runout-compensated) recorded every mounted condition three times at each of two dwell
speeds without touching the rotor: any two acquisitions are two passes of an unchanged
rotor. Each pair is compared by :func:`sknarx.gap.passes.compare_pass_features` under the
verdict rule (its dead band ``rtol``). The file holds no standard errors, so the noise is
estimated from the repeats: per probe, the squared difference of two acquisitions
regressed on the squared size, the intercept twice one record's noise variance; the
largest probe's is used for every probe. At the rule's level a test whose null holds
calls about one pair in a hundred changed.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pandas as pd

from sknarx.gap import VerdictRule
from sknarx.gap.passes import compare_pass_features

__all__ = ["repeated_pairs", "repeatability", "statistic", "main"]

PROBES = ("plane1_x", "plane1_y", "plane2_x", "plane2_y")


def repeated_pairs(frame) -> list:
    """Every pair of acquisitions of one mounted condition: ``(condition, a, b, first,
    second)``, each side's rows sorted by dwell speed (pairs of unlike dwells left out)."""
    out = []
    for cond, g in frame.groupby("condition_id", sort=True):
        for a, b in itertools.combinations(sorted(g["acq_idx"].unique()), 2):
            first = g[g["acq_idx"] == a].sort_values("speed_id")
            second = g[g["acq_idx"] == b].sort_values("speed_id")
            if list(first["speed_id"]) == list(second["speed_id"]):
                out.append((cond, int(a), int(b), first, second))
    return out


def _vectors(rows):
    return np.stack([rows[f"{p}_1x_re"].to_numpy() + 1j * rows[f"{p}_1x_im"].to_numpy()
                     for p in PROBES], axis=1)


def repeatability(pairs, keyphasor_deg: float = 5.0) -> dict:
    """Per probe: one record's noise (mil, per component) and the relative difference
    beyond it, from ``|a - b|^2 = c0 + c1 |x|^2`` over every step of every pair (the
    reference's common offset, at most ``keyphasor_deg``, removed first)."""
    lim = np.radians(keyphasor_deg)
    d, x = [], []
    for *_, first, second in pairs:
        a, b = _vectors(first), _vectors(second)
        delta = np.clip(np.angle(np.sum(a * np.conj(b), axis=1, keepdims=True)), -lim, lim)
        d.append(np.abs(a * np.exp(-1j * delta) - b))
        x.append(np.abs(a + b) / 2.0)
    d, x = np.concatenate(d), np.concatenate(x)
    out = {}
    for k, p in enumerate(PROBES):
        design = np.column_stack([np.ones(len(x)), x[:, k] ** 2])
        (c0, c1), *_ = np.linalg.lstsq(design, d[:, k] ** 2, rcond=None)
        out[p] = {"noise_mil": float(np.sqrt(max(c0, 0.0) / 4.0)),
                  "relative": float(np.sqrt(max(c1, 0.0)))}
    return out


def _features(rows, se_mil):
    z = _vectors(rows)
    speed = rows["rpm_measured"].to_numpy(dtype=float) * 2.0 * np.pi / 60.0
    return pd.DataFrame([{"speed": w, "window": "steady", "channel": p, "feature": "1x",
                          "re": z[i, k].real, "im": z[i, k].imag, "se": se_mil}
                         for i, w in enumerate(speed) for k, p in enumerate(PROBES)])


def statistic(first, second, se_mil, rule: VerdictRule) -> float:
    """The pass test's statistic of one pair under ``rule`` (over ``rule.pass_sigmas``:
    called changed)."""
    return compare_pass_features(_features(first, se_mil), _features(second, se_mil),
                                 rule).statistic


def main(argv=None) -> dict:
    from sknarx.datasets import load_rk4_unbalance

    pairs = repeated_pairs(load_rk4_unbalance().frame)
    rep = repeatability(pairs)
    se = max(v["noise_mil"] for v in rep.values())
    rule = VerdictRule()
    out = {}
    for rtol in (0.003, rule.rtol, 0.03):
        r = replace(rule, rtol=rtol)
        called = sum(statistic(f, s, se, r) > r.pass_sigmas for *_, f, s in pairs)
        out[rtol] = called
        print(f"dead band {100 * rtol:g} %: {called} of {len(pairs)} pairs of an unchanged "
              "rotor called changed")
    return out


if __name__ == "__main__":
    main()
