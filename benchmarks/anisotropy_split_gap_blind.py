"""The anisotropy's fitted x/y split on the sweeps the package calls ``no-gap``.

Run: ``python benchmarks/anisotropy_split_gap_blind.py`` (about 5 s; writes
``results/gap_blind_anisotropy_split.json``).

A soft pedestal the nominal update follows ends ``no-gap``: what it leaves on the
held-out speeds is under the noise floor. The record left one test open (docs/
gap_validation.md, *What the other single misses are*, 2026-11-29): the anisotropy
candidate, fitted on the training speeds of every sweep, puts its two support
stiffnesses far apart on such misses, so a test of that split against its own
uncertainty might tell them from effect-free sweeps. The blind runs log every
candidate's ``params_std`` since then. This reads them: on every trial of the runs the
package's rule decides (``pooled_package_rule.PACKAGE_RULE_RUNS``) whose verdict is
``no-gap``, the anisotropy entry's stiffness ratio ``max(kx, ky) / min(kx, ky)`` and
``z = |ln(kx / ky)| / hypot(std_kx / kx, std_ky / ky)``, by what the trial holds:

* ``effect-free``;
* ``followed anisotropy``: a detectable anisotropy single (the misses in question);
* ``other detectable``: another detectable in-library effect, single or pair;
* ``visible out-of-library``;
* ``undetectable``: an effect under the noise floor, counted but never scored.

Then the what-if of naming the anisotropy on a ``no-gap`` sweep whose ratio exceeds
every effect-free trial's of both plants (the smallest rule with no false alarm on these
logs, so chosen on them): the followed anisotropies it would name on the right soft
axis, the other trials it would name wrongly, and top-1 pooled with it. Analysis of
finished runs, every trial already read and scored; no threshold is set from it and
the package does not change.
"""

from __future__ import annotations

import math
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy as np  # noqa: E402
from _common import table, write_json  # noqa: E402
from bench_gap_blind import detectable, truth_label, verdict, visible  # noqa: E402
from frontier_gap_blind import pooled  # noqa: E402
from pooled_package_rule import decided_by_package_rule  # noqa: E402
from rescore_gap_blind import wilson  # noqa: E402

CLASSES = ("effect-free", "followed anisotropy", "other detectable",
           "visible out-of-library", "undetectable")


def anisotropy_split(rec):
    """``(ratio, z, soft axis)`` of the trial's anisotropy fit: its stiffer support
    over its softer, the log split over the split's standard error, and the axis of
    the softer support."""
    e = next(e for e in rec["ranking"] if e["effect"] == "anisotropy")
    kx, ky = e["params"]["kx"], e["params"]["ky"]
    sx, sy = (e["params_std"][f"anisotropy.{k}"] for k in ("kx", "ky"))
    split = abs(math.log(kx / ky))
    return math.exp(split), split / math.hypot(sx / kx, sy / ky), "x" if kx < ky else "y"


def trial_class(rec, rule):
    """Which of :data:`CLASSES` a trial is."""
    if rec["kind"] == "none":
        return "effect-free"
    if detectable(rec, rule):
        return ("followed anisotropy" if truth_label(rec, rule) == "anisotropy"
                else "other detectable")
    return "visible out-of-library" if visible(rec, rule) else "undetectable"


def no_gap_splits(decided):
    """Every ``no-gap`` trial of ``decided`` as ``{family, seed, class, ratio, z,
    axis, true_axis}`` (``true_axis`` for an anisotropy, else None)."""
    rows = []
    for rule, evals in decided:
        for fam, recs in evals.items():
            for r in recs:
                if verdict(r, rule)[0] != "no-gap":
                    continue
                ratio, z, axis = anisotropy_split(r)
                truth = r["truth"]["effects"].get("anisotropy")
                rows.append({"family": fam, "seed": r["seed"], "class": trial_class(r, rule),
                             "ratio": ratio, "z": z, "axis": axis,
                             "true_axis": truth["soft_axis"] if truth else None})
    return rows


def summary(rows, families):
    """Per family and class: the number of trials, the ratio's and z's median and
    maximum, and how many have z over 3."""
    out = {}
    for fam in families:
        for cls in CLASSES:
            sub = [r for r in rows if r["family"] == fam and r["class"] == cls]
            if not sub:
                continue
            ratio = np.array([r["ratio"] for r in sub])
            z = np.array([r["z"] for r in sub])
            out.setdefault(fam, {})[cls] = {
                "n": len(sub), "ratio_median": float(np.median(ratio)),
                "ratio_max": float(ratio.max()), "z_median": float(np.median(z)),
                "z_max": float(z.max()), "n_z_over_3": int((z > 3).sum())}
    return out


def effect_free_bar(rows):
    """The largest stiffness ratio of any effect-free trial in ``rows``: the smallest
    bar that names no anisotropy on them."""
    return max(r["ratio"] for r in rows if r["class"] == "effect-free")


def what_if(decided, rows, bar):
    """Naming the anisotropy on each ``no-gap`` trial whose ratio exceeds ``bar``: per
    family the followed anisotropies named on their soft axis (``gained``), on the other
    axis, the other trials named (by class), and top-1 ``[k, n]`` with and without it."""
    top1 = {fam: rates["top1"] for fam, rates in pooled(decided).items()}
    out = {}
    for fam in sorted({r["family"] for r in rows}):
        named = [r for r in rows if r["family"] == fam and r["ratio"] > bar]
        gained = [r["seed"] for r in named if r["class"] == "followed anisotropy"
                  and r["axis"] == r["true_axis"]]
        k, n = top1[fam]
        others = dict(Counter(r["class"] for r in named if r["class"] != "followed anisotropy"))
        out[fam] = {"gained": gained,
                    "wrong_axis": [r["seed"] for r in named if r["class"] ==
                                   "followed anisotropy" and r["axis"] != r["true_axis"]],
                    "others_named": others, "top1": [k, n], "top1_with": [k + len(gained), n]}
    return out


def main(argv=None):
    decided = decided_by_package_rule()
    families = list(decided[0][1])
    rows = no_gap_splits(decided)
    got = summary(rows, families)
    table([[fam, cls, s["n"], f"{s['ratio_median']:.1f}", f"{s['ratio_max']:.1f}",
            f"{s['z_median']:.1f}", f"{s['z_max']:.1f}", s["n_z_over_3"]]
           for fam, by in got.items() for cls, s in by.items()],
          ["family", "no-gap trials", "n", "ratio median", "ratio max", "z median",
           "z max", "z > 3"])
    bar = effect_free_bar(rows)
    found = what_if(decided, rows, bar)
    print(f"\nnaming the anisotropy on a no-gap sweep whose ratio exceeds {bar:.2f} "
          "(every effect-free trial's):")
    table([[fam, len(w["gained"]), len(w["wrong_axis"]), sum(w["others_named"].values()),
            f"{w['top1'][0]}/{w['top1'][1]}", f"{w['top1_with'][0]}/{w['top1_with'][1]}",
            "{:.2f}-{:.2f}".format(*wilson(*w["top1_with"]))]
           for fam, w in found.items()],
          ["family", "followed named", "wrong axis", "others named", "top-1",
           "top-1 with it", "95 % interval"])
    write_json("gap_blind_anisotropy_split", {
        "command": "python benchmarks/anisotropy_split_gap_blind.py",
        "by_class": got, "bar_ratio": bar, "what_if": found, "trials": rows})


if __name__ == "__main__":
    main()
