"""Order-tracked measurements (Bode data): loading, units, binning, the run-up's rate.

Most rotating-machinery users have order-tracked run-ups or coast-downs -- one 1x
amplitude and phase per revolution -- not raw time series. The rotor file's
``[measurement]`` section says how to read them (see ``examples/rk4/rotor.toml``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..io import read_table
from ..rotor.runup import RPM  # one definition, in the rotor layer the data flow from

__all__ = ["RPM", "load_bode", "bin_bode", "runup_rate"]


def load_bode(path, measurement: dict) -> pd.DataFrame:
    """One row per revolution: speed (rad/s) and the complex 1x vector (m, 0-peak).

    ``measurement`` names the columns and units (see ``examples/rk4/rotor.toml``).
    ``path`` may also be a DataFrame already read.
    """
    df = path if isinstance(path, pd.DataFrame) else read_table(path, what="Bode file")
    sc = measurement.get("speed_column", "rpm")
    ac = measurement.get("amplitude_column", "amp_1x")
    pc = measurement.get("phase_column", "phase_1x_deg")
    missing = [c for c in (sc, ac, pc) if c not in df.columns]
    if missing:
        raise ValueError(f"The Bode file lacks column(s) {missing} (found "
                         f"{list(df.columns)[:10]}); the rotor file's [measurement] section "
                         "names the speed, amplitude and phase columns.")
    d = df[[sc, ac, pc]].apply(pd.to_numeric, errors="coerce")
    if d.isna().any().any():
        raise ValueError("The Bode file has empty or non-numeric values; clean it first.")
    rpm = d[sc].to_numpy()
    amp = d[ac].to_numpy() * float(measurement.get("amplitude_scale", 1.0))
    ph = np.radians(d[pc].to_numpy())
    if np.any(rpm <= 0) or np.any(amp < 0):
        raise ValueError(f"The Bode file's speeds ({sc!r}) must be positive and its "
                         f"amplitudes ({ac!r}) non-negative; found speeds from {rpm.min():g} "
                         f"and amplitudes from {amp.min():g}: check the columns the rotor "
                         "file's [measurement] section names.")
    return pd.DataFrame({"rpm": rpm, "speed": rpm * RPM, "z": amp * np.exp(1j * ph)})


def bin_bode(rows: pd.DataFrame, width_rpm=20.0, max_n=10) -> pd.DataFrame:
    """Vector-average revolutions in speed bins, with a standard error per bin.

    The per-revolution noise is estimated from second differences of successive
    revolutions (blind to a response that varies linearly with speed, as it does
    between revolutions even near a resonance), as a running median over 31
    revolutions; a bin's standard error uses at most ``max_n`` revolutions, so the
    dense 5000 rpm plateau does not outweigh the run-up.
    """
    rows = rows.sort_values("rpm").reset_index(drop=True)
    edges = np.arange(np.floor(rows.rpm.min()), rows.rpm.max() + width_rpm, width_rpm)
    idx = np.digitize(rows.rpm, edges)
    z = rows.z.to_numpy()
    d2 = np.abs(z[2:] - 2 * z[1:-1] + z[:-2]) / np.sqrt(6.0)
    d2 = np.r_[d2[0], d2, d2[-1]]
    # median of |complex Gaussian| is sigma*sqrt(2 ln 2) per component pair
    local = pd.Series(d2).rolling(31, center=True, min_periods=5).median()
    rows["noise"] = local.to_numpy() / np.sqrt(2 * np.log(2))
    out = []
    for _, g in rows.groupby(idx):
        n = len(g)
        sigma = float(np.median(g.noise))
        out.append({"rpm": float(g.rpm.mean()), "speed": float(g.speed.mean()),
                    "z": complex(g.z.mean()), "n": n,
                    "se": sigma / np.sqrt(min(n, max_n))})
    return pd.DataFrame(out)


def runup_rate(rows: pd.DataFrame, min_rate_rpm_s: float = 5.0):
    """The run-up's angular acceleration (rpm/s) and speed range, or ``None``.

    Revolutions are one row each, so their times follow from their speeds
    (``dt = 60 / rpm``); the rate is the slope of speed against time over the
    revolutions below the final plateau. ``None`` when the speed hardly changes
    (a stepped or steady test: steady-state responses apply).
    """
    rpm = np.sort(rows.rpm.to_numpy())
    if rpm.size < 20:
        return None
    top = rpm[-1]
    ramp = rpm[rpm < top - 0.02 * (top - rpm[0])]
    if ramp.size < 10:
        return None
    t = np.cumsum(60.0 / ramp)
    rate = float(np.polyfit(t, ramp, 1)[0])
    if not rate >= min_rate_rpm_s:
        return None
    return {"rate_rpm_s": rate, "rpm_start": float(ramp[0]), "rpm_end": float(ramp[-1])}
