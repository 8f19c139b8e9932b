"""Scoring blind trials: the package's rule decides each logged trial, the truth scores it.

A logged trial (one JSON record, see :mod:`validation.trials`) holds everything the
verdict rule reads -- the gap before any candidate and its noise floor, every ranked
candidate's held-out excess, parameters added and linear-form tests, the passes'
statistic -- so any :class:`~sknarx.gap.VerdictRule` decides it again without
simulating (:func:`decide`). The rates (:func:`rates`) are those of docs/validation.md:

* **top-1**: detectable in-library singles named right;
* **pairs in the top two**: both members of a detectable pair among the two best ranked;
* **false alarms**: effect-free sweeps given anything but ``no-gap``;
* **out-of-library unexplained**: visible out-of-library effects called ``unexplained``;
* **shrink against the oracle**: median share of the gap a right verdict removes over
  what the truth itself removes;
* **names right**: of every verdict that names an effect, the right ones.

An effect is *visible* when it moves the measurement by more than :data:`VISIBLE`
held-out excess per feature (the measurement against the same plant without it, no
model-form tolerance); a pair member invisible beside its partner leaves the pair
scored as its visible member.

Run ``python -m validation.score RUN [RUN ...]`` (a run: a folder of
``<family>.jsonl.gz``): prints each family's rates with their Wilson 95 % intervals.
"""

from __future__ import annotations

import argparse
import gzip
import json
import math
from pathlib import Path

import numpy as np

from sknarx.gap import Candidate, NoiseFloor, VerdictRule

__all__ = ["VISIBLE", "read_run", "decide", "rates", "wilson", "truth_label", "candidates"]

#: an effect is visible (and an in-library one detectable) when the measurement differs
#: from the same plant without it by more than this held-out excess per feature: the
#: protocol's bar, fixed with it (the 99 % level of effect-free own-family sweeps then)
VISIBLE = 0.34
FAMILIES = ("ross", "second", "own")


def read_run(folder) -> dict:
    """``{family: [record, ...]}`` of a run's logged trials (``<family>.jsonl.gz``)."""
    out = {}
    for path in sorted(Path(folder).glob("*.jsonl.gz")):
        with gzip.open(path, "rt") as f:
            out[path.name.split(".")[0]] = [json.loads(line) for line in f if line.strip()]
    return out


def candidates(rec) -> list:
    """A record's ranking as :class:`~sknarx.gap.Candidate` objects (held-out excess,
    parameters added, breadth and linear-form tests as logged)."""
    out = []
    for r in rec["ranking"]:
        names = (r["effect"],) if isinstance(r["effect"], str) else tuple(r["effect"])
        E = float(r["E"])
        n_params = int(round((float(r["score"]) - E) / 2.0)) if math.isfinite(E) else 0
        details = {k: r[k] for k in ("linear_form_tests", "model_error") if k in r}
        out.append(Candidate(effects=names, params=r.get("params"), params_std={},
                             n_params=n_params, heldout_after=E, cmp=None, details=details,
                             heldout_before=float(rec["E0"]),
                             log_shrink=float(r["log_shrink"])))
    return out


def decide(rec, rule: VerdictRule):
    """``(verdict, shrink)`` of a logged trial under ``rule``: ``"no-gap"``,
    ``"unexplained"``, an effect's name or a pair's two names sorted."""
    passes = rec.get("passes")
    if passes is not None and passes["statistic"] > rule.pass_sigmas:
        return "unexplained", 0.0
    floor = NoiseFloor(**{k: rec["floor"][k] for k in ("floor", "median", "n_draws",
                                                        "false_alarm")})
    v = rule.decide(rec["e0"], candidates(rec), floor, rec["n_features"])
    if v.outcome != "effect":
        return v.outcome, 0.0
    names = v.candidate.effects
    return (names[0] if len(names) == 1 else sorted(names)), v.candidate.shrink


def visible(rec) -> bool:
    return rec["kind"] != "none" and rec["effect_gap"] > VISIBLE


def truth_label(rec, visible_only=True):
    """What a right verdict names: ``"no-gap"``, the effect, or the pair sorted (its
    visible member alone where the other is invisible beside it)."""
    kind = rec["kind"]
    if kind == "none":
        return "no-gap"
    if isinstance(kind, str):
        return kind
    gaps = rec.get("member_gap") or {}
    shown = [m for m in kind if gaps.get(m) is None or gaps[m] > VISIBLE] \
        if visible_only else list(kind)
    return shown[0] if len(shown) == 1 else sorted(kind)


def _top2(rec) -> set:
    return {n for r in rec["ranking"][:2]
            for n in ((r["effect"],) if isinstance(r["effect"], str) else r["effect"])}


def rates(records, rule: VerdictRule, verdict_of=None) -> dict:
    """Each rate of the module docstring as ``(successes, trials)`` (the shrink ratio:
    ``(median, n)``), with the misses of top-1 as ``(seed, truth, verdict)``.
    ``verdict_of`` (a record to its verdict) scores verdicts given otherwise, such as
    each record's ``logged_verdict`` (no shrink ratio then)."""
    got = {"top1": [0, 0], "pairs_in_top2": [0, 0], "false_alarm": [0, 0],
           "unexplained_out_of_library": [0, 0], "names_right": [0, 0]}
    ratios, misses = [], []
    for rec in records:
        verdict, shrink = decide(rec, rule) if verdict_of is None else \
            (verdict_of(rec), float("nan"))
        detectable = rec["in_library"] and visible(rec)
        truth = truth_label(rec)
        right = detectable and verdict in (truth, truth_label(rec, visible_only=False))
        if right and rec.get("oracle_shrink", 0) > 0 and shrink == shrink:
            ratios.append(shrink / rec["oracle_shrink"])
        if detectable and isinstance(truth, str):
            got["top1"][1] += 1
            got["top1"][0] += right
            if not right:
                misses.append((rec["seed"], truth, verdict))
        elif detectable:
            got["pairs_in_top2"][1] += 1
            got["pairs_in_top2"][0] += set(rec["kind"]) <= _top2(rec)
        if rec["kind"] == "none":
            got["false_alarm"][1] += 1
            got["false_alarm"][0] += verdict != "no-gap"
        if not rec["in_library"] and visible(rec):
            got["unexplained_out_of_library"][1] += 1
            got["unexplained_out_of_library"][0] += verdict == "unexplained"
        if verdict not in ("no-gap", "unexplained"):
            got["names_right"][1] += 1
            got["names_right"][0] += right
    out = {k: tuple(v) for k, v in got.items()}
    out["shrink_vs_oracle"] = (float(np.median(ratios)) if ratios else float("nan"),
                               len(ratios))
    out["top1_misses"] = misses
    return out


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of ``k`` successes in ``n`` trials (95 % by default)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def table(runs, rule: VerdictRule) -> dict:
    """Each family's rates pooled over ``runs`` (folders of logged trials)."""
    pooled: dict = {}
    for run in runs:
        for family, records in read_run(run).items():
            pooled.setdefault(family, []).extend(records)
    return {family: rates(records, rule) for family, records in sorted(pooled.items())}


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m validation.score",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="run folders of <family>.jsonl.gz logs")
    args = ap.parse_args(argv)
    missing = [r for r in args.runs if not Path(r).is_dir()]
    if missing:
        ap.error(f"no run folder {', '.join(missing)}")
    got = table(args.runs, VerdictRule())
    print(f"{'family':8s} {'rate':28s} {'k/n':>8s} {'rate':>6s}  95 % interval")
    for family, r in got.items():
        for name in ("top1", "pairs_in_top2", "false_alarm", "unexplained_out_of_library",
                     "names_right"):
            k, n = r[name]
            lo, hi = wilson(k, n)
            print(f"{family:8s} {name:28s} {f'{k}/{n}':>8s} {k / max(n, 1):6.3f}  "
                  f"{lo:.2f}-{hi:.2f}")
        median, n = r["shrink_vs_oracle"]
        print(f"{family:8s} {'shrink_vs_oracle (median)':28s} {n:>8d} {median:6.3f}")
    return got


if __name__ == "__main__":
    main()
