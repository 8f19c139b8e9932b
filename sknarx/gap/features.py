"""Order-domain features of stepped-speed records: the common currency of the gap.

For each speed step, time window (``transient``: the first ``transient_s``
seconds; ``steady``: the rest) and channel, the record is fitted by least
squares with a constant and the shaft orders 1/3x, 1/2x, 1x, 2x, 3x (plus 4x,
5x to keep them out of the residual). Each order gives a complex vector
``V = A e^{i phase}`` (``x ~ A cos(k phi + phase)``) with a standard error from
the residual; the residual's *line energy* -- power in spectral lines standing
above its white floor -- measures non-synchronous content (sidebands, electrical
lines, subharmonics not on the list) while ignoring broadband noise. It is kept
per band of shaft order (``NONSYNC_BANDS``): a fixed-frequency line (mains
pickup, a natural frequency ringing down) walks across the bands as the speed
changes, while the ball-passage line of a bearing stays in its band -- one
scalar of non-synchronous energy cannot tell the two apart.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["ORDERS", "order_features", "ORDER_LABELS", "NONSYNC_BANDS", "is_nonsync"]

ORDERS = (1 / 3, 1 / 2, 1.0, 2.0, 3.0)
ORDER_LABELS = {1 / 3: "1/3x", 1 / 2: "1/2x", 1.0: "1x", 2.0: "2x", 3.0: "3x"}
_EXTRA = (4.0, 5.0)
#: edges of the non-synchronous bands, in shaft orders (the last band is open)
NONSYNC_BANDS = (0.0, 0.75, 1.5, 2.5, 3.5)
NONSYNC_LABELS = tuple(
    f"nonsync {a:g}-{b:g}x" for a, b in zip(NONSYNC_BANDS[:-1], NONSYNC_BANDS[1:], strict=True)
) + (f"nonsync >{NONSYNC_BANDS[-1]:g}x",)


def is_nonsync(label) -> bool:
    """Whether a feature label is a non-synchronous line-energy band."""
    return str(label).startswith("nonsync")


def _line_energy(r, fs, omega):
    """Amplitude of spectral lines above the white floor of a residual, per order band.

    Returns the line amplitude of each band of ``NONSYNC_BANDS`` (units of ``r``)
    and the white-floor amplitude of one bin.
    """
    n = r.size
    nb = len(NONSYNC_LABELS)
    if n < 16:
        return np.zeros(nb), 0.0
    win = np.hanning(n)
    P = np.abs(np.fft.rfft(r * win)) ** 2
    P = P[1:]
    order = np.arange(1, P.size + 1) * fs / n * 2 * np.pi / max(omega, 1e-12)
    level = np.median(P) / np.log(2.0)  # exponential distribution of white periodogram bins
    thr = level * np.log(P.size / 1e-3)  # ~1e-3 false exceedances per record
    excess = np.where(P > thr, np.clip(P - level, 0.0, None), 0.0)
    band = np.searchsorted(NONSYNC_BANDS, order, side="right") - 1
    per_band = np.bincount(band, weights=excess, minlength=nb)[:nb]
    scale = 2.0 / (win.sum() ** 2)  # periodogram -> squared amplitude
    return np.sqrt(per_band * scale), float(np.sqrt(level * scale))


def _window_features(w, t, Y, fs, orders):
    """Order vectors, standard errors and line energies of one window (all channels)."""
    n = t.size
    phi = w * t
    all_orders = tuple(orders) + _EXTRA
    B = np.empty((n, 1 + 2 * len(all_orders)))
    B[:, 0] = 1.0
    for i, k in enumerate(all_orders):
        B[:, 1 + 2 * i] = np.cos(k * phi)
        B[:, 2 + 2 * i] = np.sin(k * phi)
    coef, *_ = np.linalg.lstsq(B, Y, rcond=None)
    R = Y - B @ coef
    dof = max(n - B.shape[1], 1)
    se = np.sqrt((R**2).sum(axis=0) / dof) * np.sqrt(2.0 / n)
    k = len(orders)
    vec = coef[1 : 1 + 2 * k : 2] - 1j * coef[2 : 2 + 2 * k : 2]  # (orders, channels)
    lines = [_line_energy(R[:, c], fs, w) for c in range(Y.shape[1])]
    return vec, se, lines


def feature_arrays(records, channels, transient_s=0.5, orders=ORDERS):
    """Features of ``records`` = [(speed, t, Y)] as aligned arrays (fast path).

    Returns ``keys`` (list of (speed, window, channel, feature)), complex values,
    standard errors and a boolean mask of the ``nonsync`` rows, always in the same
    order for the same speeds, windows and channels.
    """
    keys, vals, ses = [], [], []
    labels = [ORDER_LABELS.get(k, f"{k:g}x") for k in orders]
    for w, t, Y in records:
        fs = 1.0 / np.median(np.diff(t)) if t.size > 1 else 1.0
        for window, mask in (("transient", t < transient_s), ("steady", t >= transient_s)):
            if int(mask.sum()) < 32:
                continue
            vec, se, lines = _window_features(w, t[mask], Y[mask], fs, orders)
            for c, ch in enumerate(channels):
                for i, lab in enumerate(labels):
                    keys.append((w, window, ch, lab))
                    vals.append(vec[i, c])
                    ses.append(se[c])
                amps, floor = lines[c]
                for lab, a in zip(NONSYNC_LABELS, amps, strict=True):
                    keys.append((w, window, ch, lab))
                    vals.append(a)
                    ses.append(floor)
    nons = np.array([is_nonsync(k[3]) for k in keys])
    return keys, np.array(vals, dtype=complex), np.array(ses), nons


def order_features(table: pd.DataFrame, channels, transient_s: float = 0.5,
                   orders=ORDERS) -> pd.DataFrame:
    """Order vectors and line energy of every speed step, window and channel.

    Parameters
    ----------
    table : DataFrame
        Long table with ``speed`` (rad/s), ``t`` (s, 0 at the once-per-revolution
        reference of each step) and one column per channel (m). The shaft angle is
        ``speed * t``.
    channels : sequence of str
    transient_s : float
        Length of the transient window at the start of each step, s.

    Returns
    -------
    DataFrame
        One row per (speed, window, channel, feature): ``feature`` is an order
        label or a ``'nonsync ...'`` band; ``re``, ``im`` (m; ``im = 0`` for the
        non-synchronous bands) and
        ``se`` (standard error, m).
    """
    records = [(w, g["t"].to_numpy(), g[list(channels)].to_numpy())
               for w, g in table.groupby("speed", sort=True)]
    keys, vals, ses, _ = feature_arrays(records, list(channels), transient_s, orders)
    df = pd.DataFrame(keys, columns=["speed", "window", "channel", "feature"])
    df["re"] = vals.real
    df["im"] = vals.imag
    df["se"] = ses
    return df
