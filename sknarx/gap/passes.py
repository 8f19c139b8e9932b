"""Whether the rotor changed between two passes of one stepped sweep.

A time-invariant rotor settles to the same response at a speed however and whenever
that speed is reached: a run-up and the coast-down after it, or a repeat of the sweep,
agree within the noise and the once-per-revolution reference's jitter. A rotor that
changes over time does not: a thermal bow relaxing as the rotor's temperature evens
out, a crack growing, a joint working loose, a rub heating its spot, or a nonlinear
response that jumps between branches and depends on the way a speed was reached. Its
passes disagree, most where the change is largest.

No model enters the comparison, so no model error can hide a change. One monotone
pass cannot show it: there a bow relaxing while the speed only rises is a smooth 1x
change over speed, which the nominal update absorbs (``docs/gap.md``, *Two passes of
one sweep*). Every effect in the library is time-invariant. So a sweep whose passes
disagree is one that no candidate explains, and :func:`sknarx.gap.diagnose` says
``unexplained`` for it, whatever one pass alone would have named.

Each feature is compared as the gap map compares (:func:`sknarx.gap.gapmap.compare`):
the first pass plays the measurement and the second its twin, each with its own standard
errors, and the reference's offset is removed per speed step. A rig does not repeat a
vector to its noise: between two records of an unchanged rotor its temperature, speed
control and electronics drift (the RK-4 rig's repeated acquisitions differ by 0.2-0.7 %
of a 1x beyond their noise). So each difference is first shrunk by a dead band, the
rule's ``rtol`` (1 %) of the vectors' mean size plus, where a step moved, the first
pass's slope over speed times the move; only what is left counts, in units of the
noise. Where the passes agree to within the band, that
``z2`` is never more than the noise's own, a chi-square with two degrees of freedom per
vector, whatever the sweep holds and however much of the band the rig's drift uses. The
test is the sum of ``z2`` over the shaft orders (1/3x to 3x) of the steps both passes
hold, as the normal deviate of equal upper tail under noise alone (the Wilson-Hilferty
transform of a chi-square with two degrees of freedom per vector; ``statistic``),
against the normal point of the rule's false-alarm level
(:attr:`~sknarx.gap.VerdictRule.pass_sigmas`). A dead band, not a variance: a
difference inside a tolerance added to the variance still counts as excess over the
noise, and on the RK-4 rig's unchanged repeats that called 22 of 285 pairs changed.
The non-synchronous line energy is listed, one sum over its bands per step and channel,
but not tested: how much one line estimate scatters from record to record is not known
from a record.

Two speed steps are the same step when their speeds agree to the rule's ``speed_rtol``;
a step that a rig's speed control placed a little apart in the second pass widens the
band as above.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from ..orders import free_response_decay, is_nonsync, order_features
from .gapmap import compare, regions
from .measured import check_measured

__all__ = ["PassComparison", "compare_pass_features", "compare_passes",
           "sigmas_over_noise"]

_KEY = ["speed", "window", "channel", "feature"]


@dataclass
class PassComparison:
    """Two passes of one sweep compared feature by feature (:func:`compare_passes`).

    Attributes
    ----------
    table : DataFrame
        One row per feature of the steps both passes hold: ``speed`` (rad/s, the first
        pass's), ``window``, ``channel``, ``feature``, ``measured`` and ``simulated``
        (the first and the second pass's size, m), ``gap`` (m), ``band`` (the dead
        band, m), ``z2`` (the difference beyond the band, squared, over its noise
        variance) and ``excess`` (``z2`` over its expectation for noise alone).
    statistic : float
        The shaft orders' summed ``z2`` as the normal deviate of equal upper tail under
        noise alone.
    floor : float
        What it is tested against (the rule's ``pass_sigmas``).
    speed_pairs : list of (float, float)
        The matched steps' speeds (rad/s): first pass, second pass.
    unmatched : dict
        Speeds (rad/s) of each pass that the other pass does not hold.
    band_rtol : float
        The dead band's share of each vector's size (the rule's ``rtol``).
    region_z2 : float
        The z2 above which a feature counts toward a region where the passes differ.
    """

    table: pd.DataFrame
    statistic: float
    floor: float
    speed_pairs: list
    unmatched: dict
    band_rtol: float = 0.01
    region_z2: float = 9.21

    @property
    def changed(self) -> bool:
        """Whether the passes differ by more than the noise floor."""
        return self.statistic > self.floor

    @property
    def tested(self) -> pd.DataFrame:
        """The rows of :attr:`table` the test reads: the shaft orders."""
        return _tested(self.table)

    @property
    def z2_ratio(self) -> float:
        """The tested orders' summed ``z2`` over its expectation for noise alone: at most
        1 for two records of an unchanged rotor, on average."""
        return float(self.tested["z2"].sum() / max(2.0 * len(self.tested), 1))

    def to_dict(self, n_largest: int = 5) -> dict:
        """The document's ``passes`` entry: the test, where the passes differ
        (``where``: runs of adjacent speeds, as the gap map's regions), each order's
        mean ``z2`` and the ``n_largest`` largest differences (m)."""
        top = self.table.nlargest(n_largest, "excess")
        return {
            "changed": self.changed,
            "statistic": self.statistic, "floor_sigmas": self.floor,
            "z2_ratio": self.z2_ratio, "band_rtol": self.band_rtol,
            "n_tested": len(self.tested),
            "n_features": len(self.table), "n_steps": len(self.speed_pairs),
            "speed_pairs": [[float(a), float(b)] for a, b in self.speed_pairs],
            "unmatched_speeds": {k: [float(w) for w in v] for k, v in self.unmatched.items()},
            "by_order": _by_order(self.table),
            "where": regions(self.table, self.region_z2),
            "largest": [{"speed": float(r.speed), "window": r.window,
                         "channel": r.channel, "feature": r.feature,
                         "first_m": float(r.measured), "second_m": float(r.simulated),
                         "difference_m": float(r.gap), "z2": float(r.z2)}
                        for r in top.itertuples() if r.excess > 0],
            "rule": "each difference beyond its dead band (band_rtol of the vectors' size, "
                    "and a moved step's slope), squared over its noise; the sum over the "
                    "shaft orders (1/3x-3x) of the shared steps as the normal deviate of "
                    "equal upper tail under noise alone, against the floor; line energies "
                    "listed, not tested",
        }


def _by_order(table: pd.DataFrame) -> dict:
    """The 1x, 2x and 3x rows' mean ``z2`` with their number."""
    rows = table[table["feature"].isin(("1x", "2x", "3x"))].groupby("feature")["z2"]
    return {k: {"mean_z2": float(m), "n": int(n)}
            for k, m, n in zip(rows.mean().index, rows.mean(), rows.size(), strict=True)}


def _tested(table: pd.DataFrame) -> pd.DataFrame:
    """The shaft orders' rows of a comparison table (the line energies left out)."""
    return table[~table["feature"].map(is_nonsync).to_numpy(dtype=bool)]


def sigmas_over_noise(table: pd.DataFrame) -> float:
    """The shaft orders' summed ``z2`` of a comparison table (each the difference beyond
    its dead band over its noise) as a normal deviate: under noise alone the sum is a
    chi-square with two degrees of freedom per vector, and the Wilson-Hilferty transform
    turns it into a standard normal (its one-sided 1 % point 2.326 is the chi-square's
    to within 0.01 down to one vector); 0 without a tested vector."""
    t = _tested(table)
    if t.empty:
        return 0.0
    k = 2.0 * len(t)
    h = 2.0 / (9.0 * k)
    return float((np.cbrt(t["z2"].sum() / k) - (1.0 - h)) / np.sqrt(h))


def _beyond_band(table: pd.DataFrame, band: np.ndarray) -> pd.DataFrame:
    """The comparison ``table`` (noise-only variances) with each feature's difference
    shrunk by its dead ``band`` (m): ``z2`` and ``excess`` of what is left."""
    out = table.copy()
    gap = out["gap"].to_numpy()
    left = np.clip(gap - band, 0.0, None)
    out["band"] = band
    kept = np.divide(left, gap, out=np.zeros_like(gap), where=gap > 0)
    out["z2"] = out["z2"].to_numpy() * kept**2
    expect = np.where(out["feature"].map(is_nonsync).to_numpy(dtype=bool), 1.0, 2.0)
    out["excess"] = np.clip(out["z2"].to_numpy() - expect, 0.0, None)
    return out


def _lines_summed(features):
    """The features with each step's, window's and channel's non-synchronous bands summed
    into one line energy (``nonsync``, the root sum of squares). A fixed-frequency line
    near a band's edge splits between the two bands differently from record to record
    (a 50 Hz pickup at 1.485x can move a tenth of its energy across 1.5x between
    passes); the sum does not. The white floor is one per channel, every
    band's."""
    nons = features["feature"].map(is_nonsync).to_numpy(dtype=bool)
    bands = features[nons]
    power = (bands["re"] ** 2).groupby([bands.speed, bands.window, bands.channel],
                                       sort=False)
    lines = np.sqrt(power.sum()).rename("re").reset_index()
    lines["se"] = bands.groupby(["speed", "window", "channel"], sort=False)["se"].first(
        ).to_numpy()
    lines["im"] = 0.0
    lines["feature"] = "nonsync"
    return pd.concat([features[~nons], lines[features.columns]], ignore_index=True)


def _matched(first_speeds, second_speeds, rtol):
    """Each second-pass speed's step in the first pass (within ``rtol``, the nearest),
    as ``{second: first}``; an error where two steps of one pass match one step, or
    where no step matches."""
    first = np.asarray(first_speeds, dtype=float)
    out = {}
    for w in second_speeds:
        i = int(np.argmin(np.abs(first - w)))
        if abs(first[i] - w) <= rtol * first[i]:
            if first[i] in out.values():
                raise ValueError(
                    f"Two steps of the second pass match the first pass's {first[i]:g} "
                    f"rad/s within {100 * rtol:g} %: give each pass one record per speed "
                    "step.")
            out[float(w)] = float(first[i])
    if not out:
        lo1, hi1 = min(first_speeds), max(first_speeds)
        lo2, hi2 = min(second_speeds), max(second_speeds)
        raise ValueError(
            f"The two passes share no speed step within {100 * rtol:g} % (first: "
            f"{lo1:g}-{hi1:g} rad/s, second: {lo2:g}-{hi2:g} rad/s).")
    return out


def _speed_tolerance(first, moved):
    """Each first-pass feature's band (m) for a second-pass step that lies
    ``moved[speed]`` rad/s away: the steeper of its slopes over speed to the neighbouring
    steps of the first pass (a sweep's steps are often too far apart for a central
    difference to see a peak's flank) times that distance."""
    tol = np.zeros(len(first))
    if not any(moved.values()):
        return tol
    for _, g in first.groupby(["window", "channel", "feature"], sort=False):
        g = g.sort_values("speed")
        w = g["speed"].to_numpy()
        if w.size < 2:
            continue
        z = g["re"].to_numpy() + 1j * g["im"].to_numpy()
        steps = np.abs(np.diff(z) / np.diff(w))
        steepest = np.maximum(np.r_[steps[:1], steps], np.r_[steps, steps[-1:]])
        tol[g.index.to_numpy()] = steepest * np.abs([moved.get(s, 0.0) for s in w])
    return tol


def _rule(rule):
    from .rule import VerdictRule

    return rule or VerdictRule()


def compare_passes(first: pd.DataFrame, second: pd.DataFrame, channels=None, rule=None,
                   transient_s: float = 0.5) -> PassComparison:
    """Compare two passes of one stepped sweep, model-free.

    Parameters
    ----------
    first, second : DataFrame
        The two passes as measured long tables (``speed`` in rad/s, ``t`` in s, one
        column per channel in m; :func:`sknarx.gap.load_measured`), e.g. a run-up and
        the coast-down after it. Steps one pass lacks are left out.
    channels : sequence of str, optional
        Channels to compare (every DOF column of the first pass by default).
    rule : VerdictRule, optional
        Its ``false_alarm`` (the test's level), ``rtol`` (the dead band) and
        ``speed_rtol`` (the same step); the default's when None.
    transient_s : float, default=0.5
        The window kept apart at the start of records that start with a transient.

    Returns
    -------
    PassComparison
        ``changed`` says whether the passes differ beyond the noise floor.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from sknarx.gap.passes import compare_passes
    >>> t = np.arange(1000) / 1000.0
    >>> def one_pass(bow_m, seed):
    ...     rng = np.random.default_rng(seed)
    ...     return pd.concat([pd.DataFrame({
    ...         "speed": w, "t": t,
    ...         "xO1": (2e-5 + bow_m) * np.cos(w * t) + 1e-7 * rng.normal(size=t.size)})
    ...         for w in (100.0, 150.0, 200.0, 250.0)], ignore_index=True)
    >>> compare_passes(one_pass(0.0, 1), one_pass(0.0, 2)).changed
    False
    >>> compare_passes(one_pass(5e-6, 1), one_pass(0.0, 2)).changed
    True
    """
    rule = _rule(rule)
    first, info = check_measured(first, channels)
    channels = info["channels"]
    try:
        second, info2 = check_measured(second, channels)
    except ValueError as exc:
        # the second pass is read with the first pass's channels: say which they are
        raise ValueError(f"The second pass (read with the first pass's channels "
                         f"{list(channels)}): {exc}") from exc
    if abs(info2["fs"] - info["fs"]) > 1e-6 * info["fs"]:
        raise ValueError(f"The passes are sampled at {info['fs']:g} Hz and "
                         f"{info2['fs']:g} Hz: resample one to the other's rate.")
    match = _matched(info["speeds"], info2["speeds"], rule.speed_rtol)
    # one record length for both: a longer record's features are more precise, and
    # the standard errors would say so, but the steps then differ in what they average
    n = min(info["n_samples"], info2["n_samples"])
    first = first[first.speed.isin(list(match.values()))].groupby(
        "speed", group_keys=False).head(n)
    second = second[second.speed.isin(list(match))].groupby(
        "speed", group_keys=False).head(n)
    decay = free_response_decay(first, channels)
    transient_s = transient_s if decay["transient"].median() >= 0.5 else 0.0
    got = compare_pass_features(_lines_summed(order_features(first, channels, transient_s)),
                                _lines_summed(order_features(second, channels, transient_s)),
                                rule)
    return replace(got, unmatched={
        "first": sorted(set(info["speeds"]) - set(match.values())),
        "second": sorted(set(info2["speeds"]) - set(match))})


def compare_pass_features(first: pd.DataFrame, second: pd.DataFrame,
                          rule=None) -> PassComparison:
    """Compare two passes of one sweep given as order features, model-free: the kernel
    of :func:`compare_passes`, for passes already order-tracked (e.g. a rig's 1x Bode
    vectors of a run-up and of its coast-down).

    Parameters
    ----------
    first, second : DataFrame
        One row per feature: ``speed`` (rad/s), ``window``, ``channel``, ``feature``
        (``'1x'``, ``'2x'``, ...), ``re``, ``im`` and ``se`` (each component's standard
        error), in one unit for both (m, or the data's own: the test reads ratios).
        Steps within the rule's ``speed_rtol`` of each other are the same step.
    rule : VerdictRule, optional
        Its ``false_alarm``, ``rtol`` and ``speed_rtol`` (the default's when None).

    Returns
    -------
    PassComparison

    Examples
    --------
    >>> import pandas as pd
    >>> from sknarx.gap.passes import compare_pass_features
    >>> def bode(size):
    ...     return pd.DataFrame({"speed": [100.0, 200.0], "window": "steady",
    ...                          "channel": "x", "feature": "1x", "re": size,
    ...                          "im": 0.0, "se": 0.01})
    >>> compare_pass_features(bode([1.0, 2.0]), bode([1.005, 2.01])).changed
    False
    >>> compare_pass_features(bode([1.0, 2.0]), bode([1.2, 2.0])).changed
    True
    """
    rule = _rule(rule)
    need = {*_KEY, "re", "im", "se"}
    missing = sorted((need - set(first.columns)) | (need - set(second.columns)))
    if missing:
        raise ValueError(f"Pass features need the columns {', '.join(missing)}.")
    speeds1, speeds2 = sorted(first["speed"].unique()), sorted(second["speed"].unique())
    match = _matched(speeds1, speeds2, rule.speed_rtol)
    f1 = first[first["speed"].isin(list(match.values()))].reset_index(drop=True)
    f2 = second[second["speed"].isin(list(match))].copy()
    f2["speed"] = f2["speed"].map(match)
    moved = {match[w2]: w2 - match[w2] for w2 in match}
    slope_band = _speed_tolerance(f1, moved)
    f2 = f2.set_index(_KEY).reindex(pd.MultiIndex.from_frame(f1[_KEY])).reset_index()
    # the two records of one rotor have no model form between them: the variance is
    # their noise alone, and what a rig does not repeat is a dead band, not variance
    table = compare(f1, f2, replace(rule, rtol=0.0, harmonic_rtol=0.0))
    size = (table["measured"].to_numpy() + table["simulated"].to_numpy()) / 2.0
    table = _beyond_band(table, rule.rtol * size + slope_band)
    return PassComparison(
        table=table, statistic=sigmas_over_noise(table), floor=rule.pass_sigmas,
        speed_pairs=sorted((w1, w2) for w2, w1 in match.items()),
        unmatched={"first": sorted(set(speeds1) - set(match.values())),
                   "second": sorted(set(speeds2) - set(match))},
        band_rtol=rule.rtol, region_z2=rule.region_z2)
