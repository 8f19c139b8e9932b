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

The statistic is the gap map's (:func:`sknarx.gap.gapmap.compare`). The first pass
plays the measurement and the second its twin, each with its own standard errors.
The reference's offset is removed per speed step, and the excess of ``z2`` over its
noise expectation is taken per feature. It is averaged over every feature of the
steps both passes hold, and compared with ``pass_floor_per_feature``: the noise floor
of effect-free pairs of passes, measured and frozen like the diagnosis's own floor
(``benchmarks/bench_gap_passes.py``). Two speed steps are the same step when their
speeds agree to ``pass_speed_rtol``. A step that a rig's speed control placed a little
apart in the second pass is compared with a tolerance: the first pass's slope over
speed times the difference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .core import order_mean_z2
from .features import free_response_decay, order_features
from .gapmap import compare, gap_statistic, regions
from .measured import check_measured
from .settings import DiagnosisSettings

__all__ = ["PassComparison", "compare_passes"]

_KEY = ["speed", "window", "channel", "feature"]


@dataclass
class PassComparison:
    """Two passes of one sweep compared feature by feature (:func:`compare_passes`).

    Attributes
    ----------
    table : DataFrame
        One row per feature of the steps both passes hold: ``speed`` (rad/s, the first
        pass's), ``window``, ``channel``, ``feature``, ``measured`` and ``simulated``
        (the first and the second pass's size, m), ``gap`` (m), ``z2`` and ``excess``
        (dimensionless, as in the gap map).
    per_feature : float
        Mean excess per compared feature.
    floor : float
        The frozen noise floor it is tested against (``pass_floor_per_feature``).
    speed_pairs : list of (float, float)
        The matched steps' speeds (rad/s): first pass, second pass.
    unmatched : dict
        Speeds (rad/s) of each pass that the other pass does not hold.
    """

    table: pd.DataFrame
    per_feature: float
    floor: float
    speed_pairs: list
    unmatched: dict

    @property
    def changed(self) -> bool:
        """Whether the passes differ by more than the noise floor."""
        return self.per_feature > self.floor

    def to_dict(self, n_largest: int = 5) -> dict:
        """The document's ``passes`` entry: the test, where the passes differ
        (``where``: runs of adjacent speeds, as the gap map's regions), each order's
        mean ``z2`` and the ``n_largest`` largest differences (m)."""
        top = self.table.nlargest(n_largest, "excess")
        return {
            "changed": self.changed,
            "per_feature": self.per_feature, "floor_per_feature": self.floor,
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
            "rule": "mean excess of z2 over its noise expectation per feature of the "
                    "shared steps, against the floor of effect-free pairs of passes",
        }


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
        ``pass_floor_per_feature``, ``pass_speed_rtol`` and ``transient_s`` (the
        frozen defaults by default).

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
    f1 = order_features(first, channels, transient_s)
    f2 = order_features(second, channels, transient_s)
    f2["speed"] = f2["speed"].map(match)
    moved = {match[w2]: w2 - match[w2] for w2 in match}
    f1["model_tol"] = _speed_tolerance(f1, moved)
    f2 = f2.set_index(_KEY).reindex(pd.MultiIndex.from_frame(f1[_KEY])).reset_index()
    # the two records of one rotor have no model form between them: no harmonic
    # tolerance, the comparison's own 1 % kept for what a record cannot pin down
    table = compare(f1, f2, harmonic_rtol=0.0)
    return PassComparison(
        table=table, per_feature=gap_statistic(table) / max(len(table), 1),
        floor=settings.pass_floor_per_feature,
        speed_pairs=sorted((w1, w2) for w2, w1 in match.items()),
        unmatched={"first": sorted(set(info["speeds"]) - set(match.values())),
                   "second": sorted(set(info2["speeds"]) - set(match))})
