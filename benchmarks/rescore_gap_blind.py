"""What a blind run's logged trials would score under other verdict thresholds.

Run: ``python benchmarks/rescore_gap_blind.py --report results/bench_gap_blind_25000_f7de2a1.json
--commit f7de2a1 --what-if pair_trigger=0.33`` (paths relative to ``benchmarks/``).

The verdict is decided from the ranking after the search (:func:`sknarx.gap.core.decide`),
so a logged trial can be decided again under other thresholds without running it. The
thresholds start from the report's frozen ones; ``--what-if NAME=VALUE`` (repeatable)
changes the named ones; values are Python literals, read by the parser
``bench_gap_cost.py --peer-settings`` uses (``_common.setting_overrides``). Scores of both
are printed side by side, with every trial whose verdict changes. This is analysis of a
finished run, not an evaluation: thresholds chosen by looking at the evaluation trials are
fitted on them, so a threshold change it suggests must be frozen and run on fresh seeds
before its scores are claimed.

``--one-pass`` decides the what-if side of a run made with ``bench_gap_blind.py
--second-pass`` from the first pass alone (each trial's pass comparison left out): the
same trials with and without the coast-down.

``--without-readings`` decides the what-if side of a run made with ``bench_gap_blind.py
--reading`` from the rotor as given's entries alone (those fitted in a reading carry
``rotor_reading``): the same trials with and without the readings, the verdict's recheck
of its discrete settings being the one part a log cannot replay.

With several ``--commit`` (comma-separated) the runs' trials are pooled: meaningful only
where those commits' searches give the same answers bit for bit (a later commit that
changed nothing the search computes), which the caller must know. Each rate is also
printed as successes/trials with its Wilson 95 % interval: the sampling uncertainty of a
rate on some thirty trials is about +-0.15.

Only the decision thresholds can be changed: the others change what the search finds,
which a log cannot replay. Of the decision thresholds only ``pair_trigger`` also acts in
the search (pairs are fitted where the best single leaves more than it); the blind run
searches with 0.2 per feature whatever it decides with, so any what-if trigger from 0.2
up finds its pairs in the log, and one below is refused. A pair trial whose members'
visibility (``gap_blind_member_gaps.json``) was not computed counts both members as
visible, as the blind run's report does. The per-order floors (``order_floors_z2``, e.g.
``--what-if order_floors_z2=2.48,1.81,1.76``) act only on trials that logged their
orders' gaps (``e0_by_kind``, from the 37000 run on); the blind run searches every trial,
under the floor or not, so their rankings are there to decide from.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import fields, replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, setting_overrides, table  # noqa: E402
from bench_gap_blind import (  # noqa: E402
    EARLIER_SEARCH_PAIR_TRIGGER,
    detectable,
    read_member_gaps,
    right,
    score,
    secondary_rules,
    truth_label,
    verdict,
    with_cached_member_gap,
)

from sknarx.gap import DiagnosisSettings  # noqa: E402
from sknarx.gap.core import effect_names, shrinks_alone  # noqa: E402

#: the thresholds :func:`~sknarx.gap.core.decide` reads after the search; the other
#: settings change what the search finds, which a log cannot replay
DECISION = ("no_gap_per_feature", "order_floors_z2", "min_shrink", "noise_per_feature",
            "min_log_shrink",
            "breadth_waived_at_floor", "attribute_below_floor", "pair_trigger", "pair_gain",
            "pair_margin", "pair_rival_shrink", "linear_form_gain", "pass_floor_sigmas")
#: the decision settings that are switches (True or False)
SWITCHES = ("breadth_waived_at_floor", "attribute_below_floor")
#: the decision settings None switches off
NULLABLE = ("order_floors_z2", "pair_margin", "pair_rival_shrink", "linear_form_gain",
            "noise_per_feature")
#: each rate's denominator in :func:`bench_gap_blind.score`
COUNTS = {"top1": "n_detectable_singles", "pairs_in_top2": "n_detectable_pairs",
          "pairs_verdict": "n_detectable_pairs", "false_alarm": "n_effect_free",
          "unexplained_out_of_library": "n_out_of_library",
          # secondary: the out-of-library trials no in-library fit matches within the
          # noise floor (bench_gap_blind.within_noise_of_library)
          "unexplained_out_of_library_beyond_library": "n_out_of_library_beyond_library",
          # secondary: of every verdict that names an effect, the right ones
          "names_right": "n_named",
          # secondary: of every verdict that names an effect, those whose every named
          # effect the trial holds (a pair named by one member counts)
          "names_present": "n_named",
          # secondary: top-1 on the singles, and pairs in the top two on the pairs with
          # each member, still visible after the nominal update (bench_gap_blind.separable):
          # where the misses come from, never the targets
          "top1_separable": "n_separable_singles",
          "pairs_in_top2_separable": "n_separable_pairs"}
COLUMNS = ("top1", "pairs_in_top2", "pairs_verdict", "false_alarm",
           "unexplained_out_of_library", "shrink_vs_oracle_median")


def _checked(name: str, value):
    """A what-if value of the type its decision setting takes, or ValueError: a number
    (``pair_margin``, ``pair_rival_shrink`` and ``linear_form_gain`` also None), the
    :data:`SWITCHES` True or False, ``order_floors_z2`` three numbers (1x, 2x, 3x) or None."""
    if name in SWITCHES:
        if not isinstance(value, bool):
            raise ValueError(value)
        return value
    if value is None and name in NULLABLE:
        return None
    if name == "order_floors_z2":
        if not (isinstance(value, tuple) and len(value) == 3
                and all(_is_number(v) for v in value)):
            raise ValueError(value)
        return tuple(float(v) for v in value)
    if not _is_number(value):
        raise ValueError(value)
    return float(value)


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a proportion ``k/n`` (95 % for ``z`` 1.96)."""
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(centre - half, 0.0), min(centre + half, 1.0)


def intervals(sc):
    """Each rate of a :func:`bench_gap_blind.score` result as ``(name, k, n, lo, hi)``:
    successes, trials and the Wilson 95 % interval."""
    out = []
    for key, n_key in COUNTS.items():
        n = int(sc[n_key])
        k = int(round(sc[key] * n)) if n else 0
        out.append((key, k, n, *wilson(k, n)))
    return out


def read_report(path, ap):
    """A ``bench_gap_blind`` JSON report (``path`` relative to ``benchmarks/`` unless
    absolute); an unreadable one, or one without thresholds, is ``ap``'s error line."""
    report = Path(path)
    if not report.is_absolute():
        report = Path(__file__).resolve().parent / report
    try:
        doc = json.loads(report.read_text())
        doc["thresholds"]
    except (OSError, ValueError, KeyError) as exc:
        ap.error(f"cannot read the thresholds of {report} ({exc}); give a "
                 "bench_gap_blind JSON report")
    return doc


def reported_families(path, families, ap):
    """The families of ``families`` the report at ``path`` scored: a run's logs are
    decided only where its report says the run was complete (a run half-way through
    may have logged some of the other family's trials already)."""
    return [fam for fam in families if fam in read_report(path, ap).get("families", {})]


def frozen_thresholds(path, ap):
    """The frozen thresholds of a ``bench_gap_blind`` JSON report (see :func:`read_report`)."""
    thresholds = read_report(path, ap)["thresholds"]
    known = {f.name for f in fields(DiagnosisSettings)}
    # a report written before the breadth waiver existed was decided without it, one
    # written before the per-order floors without them, and one written before the
    # rival-pair test without it; likewise the linear-form gain and the attribution
    # under the floor (each off until it was made the default), and the shrink measured
    # against the noise (the plain shrink until 2026-12-05)
    thresholds.setdefault("noise_per_feature", None)
    thresholds.setdefault("breadth_waived_at_floor", False)
    thresholds.setdefault("order_floors_z2", None)
    thresholds.setdefault("pair_rival_shrink", None)
    thresholds.setdefault("linear_form_gain", None)
    thresholds.setdefault("attribute_below_floor", False)
    if thresholds["order_floors_z2"] is not None:  # a JSON list
        thresholds["order_floors_z2"] = tuple(thresholds["order_floors_z2"])
    return DiagnosisSettings(**{k: v for k, v in thresholds.items() if k in known})


def load(families, commit):
    """Each family's logged evaluation trials of ``commit`` (one per seed, the last
    logged), with each pair member's visibility from the member-gap cache."""
    cache = read_member_gaps()
    out = {}
    for fam in families:
        by_seed = {}
        for path in sorted(RESULTS.glob(f"gap_blind_eval_{fam}*.jsonl")):
            for line in path.read_text().splitlines():
                r = json.loads(line)
                if (any(str(r.get("commit", "")).startswith(c) for c in commit.split(","))
                        and "ranking" in r):
                    by_seed[r["seed"]] = r
        recs = [with_cached_member_gap(r, cache) for r in by_seed.values()]
        out[fam] = sorted(recs, key=lambda r: r["seed"])
    return out


def pair_statistics(recs, s):
    """Each pair verdict ``s`` gives on a detectable in-library trial, with what the
    search knew when it chose the pair: how much the best single leaves per feature,
    the pair's share of that, its score gain (AIC) and the share of the held-out gap
    its weaker member removes alone (``shrink``; None where a member was not fitted
    alone). ``kind``: ``right``, ``rival`` (the truth is a single, named in the pair) or
    ``wrong``."""
    rows = []
    for r in recs:
        got = verdict(r, s)[0]
        if not detectable(r, s) or not isinstance(got, list):
            continue
        singles = [x for x in r["ranking"] if len(effect_names(x)) <= 1]
        pair = min((x for x in r["ranking"] if len(effect_names(x)) == 2),
                   key=lambda x: x["score"])
        best = min(singles, key=lambda x: x["score"])
        alone = shrinks_alone(r["ranking"])
        weaker = [alone.get(m) for m in effect_names(pair)]
        truth = truth_label(r, s)
        rows.append({
            "seed": r["seed"], "truth": truth, "verdict": got,
            "kind": ("right" if right(r, s) else
                     "rival" if isinstance(truth, str) and truth in got else "wrong"),
            "single_left_per_feature": best["E"] / r["n_features"],
            "pair_share": pair["E"] / best["E"], "score_gain": best["score"] - pair["score"],
            "weaker_alone": None if None in weaker else min(weaker)})
    return rows


def without_readings(rec):
    """A logged trial with only the rotor as given's ranking entries (those fitted in an
    alternative reading, ``rotor_reading``, left out): the run as it would have decided
    without its readings."""
    return {**rec, "ranking": [x for x in rec["ranking"] if "rotor_reading" not in x]}


def first_pass_only(rec):
    """A logged trial measured in two passes (``bench_gap_blind.py --second-pass``) with
    its pass comparison left out: as the run would have decided from the first pass
    alone (the search is the first pass's either way)."""
    return {k: v for k, v in rec.items() if k != "passes"}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--report", required=True,
                    help="a bench_gap_blind JSON report: its frozen thresholds are the base")
    ap.add_argument("--commit", required=True,
                    help="the commit (prefix) whose logged evaluation trials to decide again; "
                    "comma-separated to pool runs whose searches are bit for bit the same")
    ap.add_argument("--what-if", action="append", default=[], metavar="NAME=VALUE",
                    help="a changed threshold (repeatable)")
    ap.add_argument("--families", default="ross,second")
    ap.add_argument("--without-readings", action="store_true",
                    help="decide the what-if side from the rotor as given's entries alone "
                         "(a run with bench_gap_blind --reading: its entries fitted in a "
                         "reading carry it), so the two sides are the run with and "
                         "without its readings")
    ap.add_argument("--one-pass", action="store_true",
                    help="decide the what-if side from the first pass alone (a run with "
                         "bench_gap_blind --second-pass: its pass comparison left out), so "
                         "the two sides are the run with and without its second pass")
    ap.add_argument("--pairs", action="store_true",
                    help="also list every pair verdict (under the what-if thresholds) with "
                    "what the search knew when it chose it (pair_statistics)")
    args = ap.parse_args(argv)
    frozen = frozen_thresholds(args.report, ap)
    changes = setting_overrides(args.what_if, DECISION, ap, "--what-if", "pair_trigger=0.33",
                                fields_are=f"a decision threshold ({', '.join(DECISION)})")
    for name, value in changes.items():
        try:
            changes[name] = _checked(name, value)
        except ValueError:
            ap.error(f"--what-if {name}: {value!r} is not a number (None for "
                     f"{', '.join(NULLABLE)}, True or False for {' and '.join(SWITCHES)}, "
                     "three comma-separated numbers for order_floors_z2)")
    searched = read_report(args.report, ap).get("search_pair_trigger",
                                                EARLIER_SEARCH_PAIR_TRIGGER)
    if changes.get("pair_trigger", searched) < searched:
        ap.error(f"--what-if pair_trigger below {searched} (the blind run's own "
                 "search trigger): the log has no pairs to decide with")
    other = replace(frozen, **changes)
    evals = load(reported_families(args.report, args.families.split(","), ap), args.commit)
    if not any(evals.values()):
        ap.error(f"no logged evaluation trials of commit {args.commit!r} in {RESULTS}")
    rows, changed, counted = [], [], []
    for fam, recs in evals.items():
        theirs = [without_readings(r) for r in recs] if args.without_readings else recs
        theirs = [first_pass_only(r) for r in theirs] if args.one_pass else theirs
        for label, s, rs in (("frozen", frozen, recs), ("what-if", other, theirs)):
            sc = score(rs, s)
            rows.append([fam, label, len(recs)] + [f"{sc[k]:.2f}" for k in COLUMNS])
            if label == "frozen" or changes or args.without_readings or args.one_pass:
                # counts to pool runs by, under either
                counted += [[fam, f"{key}{'' if label == 'frozen' else ' (what-if)'}",
                             f"{k}/{n}", f"{sc[key]:.2f}", f"{lo:.2f}-{hi:.2f}"]
                            for key, k, n, lo, hi in intervals(sc)]
        for r, t in zip(recs, theirs, strict=True):
            a, b = verdict(r, frozen)[0], verdict(t, other)[0]
            if a != b:
                changed.append([fam, r["seed"], json.dumps(truth_label(r, frozen)),
                                json.dumps(a), json.dumps(b)])
    floor = read_report(args.report, ap).get("noise_floor", {})
    secondary = secondary_rules(floor.get("null_e0_median"))
    for fam, recs in evals.items():
        for name, rule in secondary.items():
            sc = score(recs, frozen, rule)
            counted += [[fam, f"{key} ({name})", f"{k}/{n}", f"{sc[key]:.2f}",
                         f"{lo:.2f}-{hi:.2f}"] for key, k, n, lo, hi in intervals(sc)]
    print("what-if:", ", ".join([*(f"{k}={v}" for k, v in changes.items()),
                                 *(["without the readings"] if args.without_readings else []),
                                 *(["the first pass alone"] if args.one_pass else [])])
          or "(nothing)")
    table(rows, ["family", "thresholds", "trials", *COLUMNS])
    print()
    table(counted, ["family", "rate (frozen unless said)", "k/n", "rate",
                    "95 % interval (Wilson)"])
    print()
    if changed:
        table(changed, ["family", "seed", "truth", "frozen verdict", "what-if verdict"])
    else:
        print("no verdict changes")
    if args.pairs:
        print()
        table([[fam, p["seed"], json.dumps(p["truth"]), json.dumps(p["verdict"]), p["kind"],
                f"{p['single_left_per_feature']:.3g}", f"{p['pair_share']:.2f}",
                f"{p['score_gain']:.0f}",
                "-" if p["weaker_alone"] is None else f"{p['weaker_alone']:.2f}"]
               for fam, recs in evals.items() for p in pair_statistics(recs, other)],
              ["family", "seed", "truth", "pair verdict (what-if)", "kind",
               "single leaves /feature", "pair's share", "AIC gain", "weaker alone"])


if __name__ == "__main__":
    main()
