"""Measured stepped-speed data: the documented file format, loading and checks."""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..io import read_table
from ..rotor.parameters import DOF_NAMES

__all__ = ["load_measured", "check_measured"]

TRANSLATIONAL = tuple(n for n in DOF_NAMES if not n.startswith("t"))


def load_measured(path) -> pd.DataFrame:
    """Read a measured long table from CSV (any common delimiter) or parquet.

    See ``docs/gap.md`` for the columns; errors say what is wrong with the file.
    """
    return read_table(path, what="measured data")


def check_measured(df: pd.DataFrame, channels=None):
    """Validate the table; returns it (sorted) and what the diagnosis needs to know."""
    if not isinstance(df, pd.DataFrame):
        raise TypeError("measured data must be a pandas DataFrame (long format).")
    missing = [c for c in ("speed", "t") if c not in df.columns]
    if missing:
        raise ValueError(
            f"Measured data lack column(s) {missing} (found {list(df.columns)[:10]}). "
            "Expected: 'speed' (rad/s), 't' (s, 0 at the once-per-revolution reference of "
            f"each speed step) and one column per channel named after a DOF "
            f"({', '.join(TRANSLATIONAL)}), in metres."
        )
    found = [c for c in df.columns if c in TRANSLATIONAL]
    if channels is None:
        channels = found
    unknown = [c for c in channels if c not in TRANSLATIONAL]
    if unknown:
        raise ValueError(f"Unknown channel(s) {unknown}; channels are named after DOFs: "
                         f"{', '.join(TRANSLATIONAL)}.")
    if not channels:
        raise ValueError(f"No measured channel column found (columns: {list(df.columns)[:10]}); "
                         "name one column per channel after its DOF "
                         f"({', '.join(TRANSLATIONAL)}), in metres.")
    absent = [c for c in channels if c not in df.columns]
    if absent:
        raise ValueError(f"Channel(s) {absent} not in the data (columns: "
                         f"{list(df.columns)[:10]}); give them, or choose the channels the "
                         "data hold (--channels, or channels=).")
    cols = ["speed", "t", *channels]
    bad = [c for c in cols if not np.all(np.isfinite(pd.to_numeric(df[c], errors="coerce")))]
    if bad:
        raise ValueError(f"Column(s) {bad} contain NaN, inf or non-numbers; clean them first.")
    df = df[cols].astype(float).sort_values(["speed", "t"], kind="stable").reset_index(drop=True)
    if (df["speed"] <= 0).any():
        raise ValueError("Speeds must be positive (rad/s); stepped-speed records only.")
    amp = df[list(channels)].abs().max().max()
    if amp > 0.05:
        raise ValueError(f"A displacement of {amp:g} m is implausible: are the channels in "
                         "metres (not um or mils)?")
    speeds = np.unique(df["speed"])
    if speeds.size < 4:
        raise ValueError(f"{speeds.size} speed step(s): at least 4 are needed (every other one to "
                         "calibrate, the others held out between them).")
    sizes, rates = [], []
    for w, g in df.groupby("speed"):
        t = g["t"].to_numpy()
        if np.unique(t).size < t.size:
            # two records at one speed (a run-down after the run-up, a repeat) sort into
            # each other by t; name that rather than the unordered times it leaves
            raise ValueError(f"Speed step {w:g} rad/s holds more than one record (its t "
                             "values repeat): the diagnosis takes one record per speed "
                             "step; keep one of them, or diagnose each pass on its own.")
        dt = np.diff(t)
        if dt.size < 64 or np.any(dt <= 0):
            raise ValueError(f"Speed step {w:g} rad/s: needs at least 65 samples with strictly "
                             "increasing t.")
        if np.ptp(dt) > 1e-6 * np.mean(dt):
            raise ValueError(f"Speed step {w:g} rad/s is not uniformly sampled; resample it.")
        sizes.append(len(g))
        rates.append(1.0 / np.mean(dt))
    if np.ptp(rates) > 1e-6 * np.mean(rates):
        by_rate = ", ".join(f"{r:g} Hz at {w:g} rad/s" for w, r in zip(speeds, rates,
                                                                        strict=True))
        raise ValueError(f"All speed steps must share one sampling rate ({by_rate}); "
                         "resample them to one rate.")
    n = int(min(sizes))
    df = df.groupby("speed", group_keys=False).head(n).reset_index(drop=True)
    fs = float(rates[0])
    _check_speed_unit(df, channels, fs, n)
    return df, {"channels": list(channels), "speeds": speeds.tolist(), "fs": fs,
                "n_samples": n}


#: rpm per rad/s: a speed column in rpm reads this much too high as rad/s
_RPM_PER_RAD_S = 60.0 / (2.0 * np.pi)


def _check_speed_unit(df, channels, fs, n):
    """A speed column in rpm, the usual unit of a rig's tachometer, is the mistake a
    diagnosis in rad/s would run an hour on and blame an effect for: every step's 1x
    would be modelled 9.55 times too fast. The records show it: their strongest line then
    sits at speed/60 Hz rather than at speed/(2 pi) Hz. Called when that holds at most
    steps where the two are more than two frequency bins apart (a record's resolution)."""
    bin_hz = fs / n
    votes, told = 0, 0
    for w, g in df.groupby("speed"):
        as_rad_s, as_rpm = w / (2.0 * np.pi), w / 60.0
        if as_rad_s > fs / 2 or abs(as_rad_s - as_rpm) <= 2 * bin_hz:
            continue
        x = g[list(channels)].to_numpy()
        power = (np.abs(np.fft.rfft(x - x.mean(axis=0), axis=0)) ** 2).sum(axis=1)
        power[0] = 0.0
        peak = np.argmax(power) * bin_hz
        told += 1
        votes += abs(peak - as_rpm) <= bin_hz and abs(peak - as_rad_s) > bin_hz
    if told and votes >= max(2, 0.75 * told):
        raise ValueError(
            f"The records' strongest line sits at speed/60 Hz at {votes} of {told} speed "
            f"steps, not at speed/(2 pi) Hz: the speed column looks like rpm. Give it in "
            f"rad/s (rpm / {_RPM_PER_RAD_S:.4f}).")

