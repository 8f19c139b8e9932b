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

Each feature is compared as the gap map compares (:func:`sknarx.gap.gapmap.compare`).
The first pass plays the measurement and the second its twin, each with its own standard
errors, and the reference's offset is removed per speed step. Where the passes agree, a
shaft order's ``z2`` is its noise share of the variance times a chi-square with two
degrees of freedom. The relative tolerance (``pass_rtol``, 1 % of each vector's size,
the gap map's) is the rest of the variance, and it is no random part. So the sum of
``z2`` over the shaft orders (1/3x to 3x) of the steps both passes hold has a known mean
and variance whatever the sweep holds: a rotor whose harmonics stand far above the
noise, or one whose records are noise but for the 1x. The test is that sum's excess over
its mean, in standard deviations (``statistic``), against ``pass_floor_sigmas``. That
floor is the larger of the one-sided 1 % point of a normal and that of effect-free pairs
of passes, measured and frozen like the diagnosis's own floor
(``benchmarks/bench_gap_passes.py``). The non-synchronous line energy is listed, one sum
over its bands per step and channel, but not tested: how much one line estimate scatters
from record to record is not known from a record.

Two speed steps are the same step when their speeds agree to ``pass_speed_rtol``. A step
that a rig's speed control placed a little apart in the second pass is compared with a
tolerance: the first pass's slope over speed times the difference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .core import order_mean_z2
from .features import free_response_decay, is_nonsync, order_features
from .gapmap import compare, regions
from .measured import check_measured
from .settings import DiagnosisSettings

__all__ = ["PassComparison", "compare_passes", "sigmas_over_noise"]

_KEY = ["speed", "window", "channel", "feature"]


@dataclass
class PassComparison:
    """Two passes of one sweep compared feature by feature (:func:`compare_passes`).

    Attributes
    ----------
    table : DataFrame
        One row per feature of the steps both passes hold: ``speed`` (rad/s, the first
        pass's), ``window``, ``channel``, ``feature``, ``measured`` and ``simulated``
        (the first and the second pass's size, m), ``gap`` (m), ``z2``, ``excess`` and
        ``noise_share`` (dimensionless, as in the gap map).
    statistic : float
        The shaft orders' summed ``z2`` over its expectation where the passes agree, in
        standard deviations of that sum.
    floor : float
        What it is tested against (``pass_floor_sigmas``).
    speed_pairs : list of (float, float)
        The matched steps' speeds (rad/s): first pass, second pass.
    unmatched : dict
        Speeds (rad/s) of each pass that the other pass does not hold.
    """

    table: pd.DataFrame
    statistic: float
    floor: float
    speed_pairs: list
    unmatched: dict

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
        """The tested orders' summed ``z2`` over its expectation where the passes agree:
        1 for two records of an unchanged rotor, on average."""
        t = self.tested
        return float(t["z2"].sum() / max(2.0 * t["noise_share"].sum(), 1e-300))

    def to_dict(self, n_largest: int = 5) -> dict:
        """The document's ``passes`` entry: the test, where the passes differ
        (``where``: runs of adjacent speeds, as the gap map's regions), each order's
        mean ``z2`` and the ``n_largest`` largest differences (m)."""
        top = self.table.nlargest(n_largest, "excess")
        return {
            "changed": self.changed,
            "statistic": self.statistic, "floor_sigmas": self.floor,
            "z2_ratio": self.z2_ratio, "n_tested": len(self.tested),
            "n_features": len(self.table), "n_steps": len(self.speed_pairs),
            "speed_pairs": [[float(a), float(b)] for a, b in self.speed_pairs],
            "unmatched_speeds": {k: [float(w) for w in v] for k, v in self.unmatched.items()},
            "by_order": order_mean_z2(self.table),
            "where": regions(self.table),
            "largest": [{"speed": float(r.speed), "window": r.window,
                         "channel": r.channel, "feature": r.feature,
                         "first_m": float(r.measured), "second_m": float(r.simulated),
                         "difference_m": float(r.gap), "z2": float(r.z2)}
                        for r in top.itertuples() if r.excess > 0],
            "rule": "the summed z2 of the shaft orders (1/3x-3x) of the shared steps over "
                    "its expectation where the passes agree, in standard deviations, "
                    "against the floor; line energies listed, not tested",
        }


def _tested(table: pd.DataFrame) -> pd.DataFrame:
    """The shaft orders' rows of a comparison table (the line energies left out)."""
    return table[~table["feature"].map(is_nonsync).to_numpy(dtype=bool)]


def sigmas_over_noise(table: pd.DataFrame) -> float:
    """The shaft orders' summed ``z2`` of a comparison table over its expectation where
    the two sides agree, in standard deviations: each vector's ``z2`` is then its
    ``noise_share`` times a chi-square with two degrees of freedom (mean ``2 s``,
    variance ``4 s^2``); 0 without a vector that noise can move."""
    t = _tested(table)
    s = t["noise_share"].to_numpy()
    sd = 2.0 * np.sqrt(np.sum(s**2))
    return float((t["z2"].sum() - 2.0 * s.sum()) / sd) if sd > 0 else 0.0


def _lines_summed(features):
    """The features with each step's, window's and channel's non-synchronous bands summed
    into one line energy (``nonsync``, the root sum of squares). A fixed-frequency line
    near a band's edge splits between the two bands differently from record to record
    (on ROSS's trial 51048 a 50 Hz pickup at 1.485x moved a tenth of its energy across
    1.5x between passes); the sum does not. The white floor is one per channel, every
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
    as ``{second: first}``; an error where two steps of one pass match one step."""
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
    return out


def _speed_tolerance(first, moved):
    """Each first-pass feature's tolerance (m) for a second-pass step that lies
    ``moved[speed]`` rad/s away: the size of the feature's slope over speed (central
    differences over the first pass's steps) times that distance."""
    tol = np.zeros(len(first))
    if not any(moved.values()):
        return tol
    for _, g in first.groupby(["window", "channel", "feature"], sort=False):
        g = g.sort_values("speed")
        w = g["speed"].to_numpy()
        if w.size < 2:
            continue
        z = g["re"].to_numpy() + 1j * g["im"].to_numpy()
        slope = np.gradient(z, w)
        tol[g.index.to_numpy()] = np.abs(slope) * np.abs([moved.get(s, 0.0) for s in w])
    return tol


def compare_passes(first: pd.DataFrame, second: pd.DataFrame, channels=None,
                   settings: DiagnosisSettings | None = None) -> PassComparison:
    """Compare two passes of one stepped sweep, model-free.

    Parameters
    ----------
    first, second : DataFrame
        The two passes as measured long tables (``speed`` in rad/s, ``t`` in s, one
        column per channel in m; :func:`sknarx.gap.load_measured`), e.g. a run-up and
        the coast-down after it. Steps one pass lacks are left out.
    channels : sequence of str, optional
        Channels to compare (every DOF column of the first pass by default).
    settings : DiagnosisSettings, optional
        ``pass_floor_sigmas``, ``pass_speed_rtol``, ``pass_rtol`` and ``transient_s``
        (the frozen defaults by default).

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
    settings = settings or DiagnosisSettings()
    first, info = check_measured(first, channels)
    channels = info["channels"]
    try:
        second, info2 = check_measured(second, channels)
    except ValueError as exc:
        raise ValueError(f"The second pass: {exc}") from exc
    if abs(info2["fs"] - info["fs"]) > 1e-6 * info["fs"]:
        raise ValueError(f"The passes are sampled at {info['fs']:g} Hz and "
                         f"{info2['fs']:g} Hz: resample one to the other's rate.")
    match = _matched(info["speeds"], info2["speeds"], settings.pass_speed_rtol)
    if not match:
        raise ValueError(
            f"The two passes share no speed step within {100 * settings.pass_speed_rtol:g} "
            f"% (first: {info['speeds'][0]:g}-{info['speeds'][-1]:g} rad/s, second: "
            f"{info2['speeds'][0]:g}-{info2['speeds'][-1]:g} rad/s).")
    # one record length for both: a longer record's features are more precise, and
    # the standard errors would say so, but the steps then differ in what they average
    n = min(info["n_samples"], info2["n_samples"])
    first = first[first.speed.isin(list(match.values()))].groupby(
        "speed", group_keys=False).head(n)
    second = second[second.speed.isin(list(match))].groupby(
        "speed", group_keys=False).head(n)
    decay = free_response_decay(first, channels)
    transient_s = settings.transient_s if decay["transient"].median() >= 0.5 else 0.0
    f1 = _lines_summed(order_features(first, channels, transient_s))
    f2 = _lines_summed(order_features(second, channels, transient_s))
    f2["speed"] = f2["speed"].map(match)
    moved = {match[w2]: w2 - match[w2] for w2 in match}
    f1["model_tol"] = _speed_tolerance(f1, moved)
    f2 = f2.set_index(_KEY).reindex(pd.MultiIndex.from_frame(f1[_KEY])).reset_index()
    # the two records of one rotor have no model form between them: no harmonic
    # tolerance, the relative one kept for what a record cannot pin down
    table = compare(f1, f2, rtol=settings.pass_rtol, harmonic_rtol=0.0)
    return PassComparison(
        table=table, statistic=sigmas_over_noise(table),
        floor=settings.pass_floor_sigmas,
        speed_pairs=sorted((w1, w2) for w2, w1 in match.items()),
        unmatched={"first": sorted(set(info["speeds"]) - set(match.values())),
                   "second": sorted(set(info2["speeds"]) - set(match))})
