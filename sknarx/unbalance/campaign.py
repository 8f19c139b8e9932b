"""An unbalance campaign: 1x response changes per condition, their labels, and how
the campaign is scored (its own definitions, from the rotor file)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

__all__ = ["Campaign", "CampaignScoring", "load_campaign", "check_trial_runs",
           "influence_from_trial_runs", "MIL_M", "GMM_KGM"]

MIL_M = 25.4e-6  # one mil in metres
GMM_KGM = 1e-6  # one g mm in kg m


@dataclass
class Campaign:
    """Per condition: the mean response change of every channel and its labels.

    ``z`` (n_conditions, n_channels) complex, in the file's units and phase convention
    (NaN where a speed was not recorded); channels are ``(speed_id, probe)`` pairs;
    ``U`` (n_conditions, 2) complex applied unbalance in g mm (NaN when sealed).
    """

    conditions: list
    channels: list
    z: np.ndarray
    U: np.ndarray
    labeled: np.ndarray
    block: np.ndarray
    speeds_rpm: dict
    n_records: np.ndarray

    def subset(self, mask) -> Campaign:
        """The conditions where ``mask`` is True (same channels and speeds)."""
        mask = np.asarray(mask, dtype=bool)
        return replace(self, conditions=[c for c, m in zip(self.conditions, mask,
                                                              strict=True) if m],
                       z=self.z[mask], U=self.U[mask], labeled=self.labeled[mask],
                       block=self.block[mask], n_records=self.n_records[mask])


def load_campaign(source, probes=None, response="resp") -> Campaign:
    """Read a 1x feature table (``sknarx.datasets.load_rk4_unbalance`` format).

    Parameters
    ----------
    source : path or DataFrame
        One row per record with ``condition_id``, ``speed_id``, ``rpm``, ``labeled``,
        ``block`` (``'baseline'`` for the balanced reference records, which no fold
        scores), ``U1_re/_im``, ``U2_re/_im`` (g mm) and ``<probe>_<response>_re/_im``.
    probes : sequence of str, optional
        The probes to read; default: every probe the table has both columns of.
    response : str
        ``'resp'`` (the change from the balanced baseline) or ``'1x'``.
    """
    from ..io import read_table

    df = source if isinstance(source, pd.DataFrame) else read_table(source, "feature table")
    if probes is None:
        tail = f"_{response}_re"
        probes = [c[: -len(tail)] for c in df.columns
                  if c.endswith(tail) and f"{c[: -len(tail)]}_{response}_im" in df.columns]
        if not probes:
            raise ValueError(f"The feature table has no probe columns '<probe>{tail}' and "
                             f"'<probe>_{response}_im' (found {list(df.columns)[:8]}...); see "
                             "sknarx.datasets.load_rk4_unbalance for the format.")
    need = ["condition_id", "speed_id", "rpm", "labeled", "block", "U1_re", "U1_im", "U2_re",
            "U2_im"] + [f"{p}_{response}_{part}" for p in probes for part in ("re", "im")]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise ValueError(f"The feature table lacks column(s) {missing[:6]} (found "
                         f"{list(df.columns)[:8]}...); see sknarx.datasets.load_rk4_unbalance "
                         "for the format.")
    speed_ids = sorted(df["speed_id"].astype(str).unique())
    speeds_rpm = {s: float(df.loc[df.speed_id == s, "rpm"].mean()) for s in speed_ids}
    channels = [(s, p) for s in speed_ids for p in probes]
    conds = list(dict.fromkeys(df["condition_id"]))
    z = np.full((len(conds), len(channels)), np.nan + 0j)
    n = np.zeros(len(conds), dtype=int)
    first = df.groupby("condition_id", sort=False).first()
    for i, c in enumerate(conds):
        g = df[df.condition_id == c]
        n[i] = len(g)
        for j, (s, p) in enumerate(channels):
            rows = g[g.speed_id == s]
            if len(rows):
                z[i, j] = np.mean(rows[f"{p}_{response}_re"] + 1j * rows[f"{p}_{response}_im"])
    U = np.stack([first.loc[conds, "U1_re"] + 1j * first.loc[conds, "U1_im"],
                  first.loc[conds, "U2_re"] + 1j * first.loc[conds, "U2_im"]], axis=1)
    U = U.to_numpy() if hasattr(U, "to_numpy") else np.asarray(U)
    labeled = first.loc[conds, "labeled"].to_numpy().astype(bool)
    U[~labeled] = np.nan
    return Campaign(conditions=conds, channels=channels, z=z, U=U.astype(complex),
                    labeled=labeled, block=first.loc[conds, "block"].to_numpy().astype(str),
                    speeds_rpm=speeds_rpm, n_records=n)


def check_trial_runs(campaign: Campaign, trial_runs) -> list[int]:
    """The rows of ``campaign`` holding the trial runs, one per disk in disk order, or a
    ``ValueError`` naming a run that is not in the campaign or has no known unbalance on
    its disk.

    Examples
    --------
    >>> from sknarx.datasets import load_rk4_unbalance
    >>> from sknarx.unbalance.campaign import check_trial_runs, load_campaign
    >>> campaign = load_campaign(load_rk4_unbalance().frame)
    >>> [campaign.conditions[i] for i in check_trial_runs(campaign, ("A007", "A015"))]
    ['A007', 'A015']
    >>> check_trial_runs(campaign, ("A015", "A007"))
    Traceback (most recent call last):
    ...
    ValueError: Trial run 'A015' has no known unbalance on disk 1: name a labelled ...
    """
    unknown = [c for c in trial_runs if c not in campaign.conditions]
    if unknown:
        raise ValueError(f"The trial runs {unknown} are not conditions of the campaign; name "
                         "one labelled trial-mass run per disk of it.")
    rows = [campaign.conditions.index(c) for c in trial_runs]
    for d, (cid, i) in enumerate(zip(trial_runs, rows, strict=True)):
        u = campaign.U[i, d]
        if not np.isfinite(u) or u == 0:
            raise ValueError(f"Trial run {cid!r} has no known unbalance on disk {d + 1}: "
                             "name a labelled condition with a trial mass on that disk, in "
                             "disk order.")
    return rows


def influence_from_trial_runs(campaign: Campaign, trial1: str, trial2: str) -> np.ndarray:
    """The classical influence-coefficient matrix from one trial-mass run per disk."""
    rows = check_trial_runs(campaign, (trial1, trial2))
    cols = [campaign.z[i] / campaign.U[i, d] for d, i in enumerate(rows)]
    return np.stack(cols, axis=1)



@dataclass(frozen=True)
class CampaignScoring:
    """How a campaign is scored and which records the influence-coefficient peer uses:
    the campaign's own definitions, given by the rotor file's ``[unbalance]`` section
    (``examples/rk4/rotor.toml``), not by the library.

    ``loaded_gmm``: a disk counts as loaded from this unbalance (g mm);
    ``phase_from_gmm``: the phase error is scored where the applied unbalance reaches
    this (g mm); ``trial_runs``: one labelled condition per disk with a trial mass on that
    disk alone; ``thresholds_gmm``: the detection thresholds searched on the labelled
    conditions (default: six from 7/12 of ``loaded_gmm`` up to it).

    Examples
    --------
    >>> from sknarx.unbalance import CampaignScoring
    >>> spec = {"loaded_gmm": 6.0, "phase_from_gmm": 24.0, "trial_runs": ["A007", "A015"]}
    >>> CampaignScoring.from_config({"unbalance": spec}).thresholds_gmm
    (3.5, 4.0, 4.5, 5.0, 5.5, 6.0)
    >>> CampaignScoring.from_config({"unbalance": {"loaded_gmm": 6.0}})
    Traceback (most recent call last):
    ...
    ValueError: The rotor file's [unbalance] section lacks phase_from_gmm, trial_runs (e.g. ...
    """

    loaded_gmm: float
    phase_from_gmm: float
    trial_runs: tuple[str, str]
    thresholds_gmm: tuple[float, ...]

    @classmethod
    def from_config(cls, cfg: dict) -> CampaignScoring:
        spec = cfg.get("unbalance")
        example = ("e.g. [unbalance] loaded_gmm = 6.0, phase_from_gmm = 24.0, trial_runs = "
                   "[\"A007\", \"A015\"] as in examples/rk4/rotor.toml")
        if not isinstance(spec, dict):
            raise ValueError("The rotor file needs an [unbalance] section: the campaign's "
                             f"scoring and its trial runs ({example}).")
        missing = [k for k in ("loaded_gmm", "phase_from_gmm", "trial_runs") if k not in spec]
        if missing:
            raise ValueError(f"The rotor file's [unbalance] section lacks {', '.join(missing)} "
                             f"({example}).")
        try:
            loaded, phase_from = float(spec["loaded_gmm"]), float(spec["phase_from_gmm"])
            thresholds = [float(t) for t in spec.get("thresholds_gmm", ())]
        except (TypeError, ValueError):
            raise ValueError("The rotor file's [unbalance] loaded_gmm, phase_from_gmm and "
                             "thresholds_gmm must be numbers (g mm).") from None
        runs = spec["trial_runs"]
        if isinstance(runs, str) or len(runs) != 2:
            raise ValueError("The rotor file's [unbalance] trial_runs names two conditions, "
                             f"one trial-mass run per disk, got {runs!r}.")
        if not loaded > 0 or not phase_from >= 0 or any(t <= 0 for t in thresholds):
            raise ValueError("The rotor file's [unbalance] loaded_gmm and thresholds_gmm must "
                             "be positive and phase_from_gmm not negative (g mm).")
        # the campaign's own definition is always among the thresholds searched: the
        # penalty is chosen at it
        thresholds = thresholds or [loaded * k / 12 for k in range(7, 12)]
        return cls(loaded, phase_from, (str(runs[0]), str(runs[1])),
                   tuple(sorted({*thresholds, loaded})))
