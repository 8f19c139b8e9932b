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

from ..orders import harmonic_basis

__all__ = ["ORDERS", "order_features", "ORDER_LABELS", "NONSYNC_BANDS", "is_nonsync",
           "free_response_decay", "TRANSIENT_RATIO"]

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


def _line_energy(R, fs, omega):
    """Amplitude of spectral lines above the white floor of residuals, per order band.

    ``R`` holds one residual per column. Returns the line amplitudes, shape
    ``(channels, bands)`` with the bands of ``NONSYNC_BANDS`` (units of ``R``), and the
    white-floor amplitude of one bin per channel.
    """
    n, n_ch = R.shape
    nb = len(NONSYNC_LABELS)
    if n < 16:
        return np.zeros((n_ch, nb)), np.zeros(n_ch)
    win = np.hanning(n)
    # all channels in one transform: each column is transformed exactly as on its own
    P = np.abs(np.fft.rfft(R * win[:, None], axis=0)) ** 2
    P = P[1:]
    order = np.arange(1, P.shape[0] + 1) * fs / n * 2 * np.pi / max(omega, 1e-12)
    level = np.median(P, axis=0) / np.log(2.0)  # exponential law of white periodogram bins
    thr = level * np.log(P.shape[0] / 1e-3)  # ~1e-3 false exceedances per record
    excess = np.where(P > thr, np.clip(P - level, 0.0, None), 0.0)
    band = np.searchsorted(NONSYNC_BANDS, order, side="right") - 1
    per_band = np.stack([np.bincount(band, weights=excess[:, c], minlength=nb)[:nb]
                         for c in range(n_ch)])
    scale = 2.0 / (win.sum() ** 2)  # periodogram -> squared amplitude
    return np.sqrt(per_band * scale), np.sqrt(level * scale)


#: a record starts with a transient when the residual of its synchronous fit is this many
#: times larger in its first eighth than in its second half (measured: 1.1-1.2 for
#: settled records, 4.3 and more for records started from rest at SNR 20 dB; the ratio
#: of two RMS estimates of ~100 noise samples each scatters by ~10 %)
TRANSIENT_RATIO = 2.0
_QUIET_RATIO = 1.5  # a block within 50 % of the tail's residual level has settled


def free_response_decay(table: pd.DataFrame, channels, n_blocks: int = 8) -> pd.DataFrame:
    """How much free (non-synchronous) response each speed step starts with.

    Whether a record is a settled steady state or starts with a transient is read from
    the record itself, not assumed from its time axis: each step's channels are fitted
    with the shaft orders on the record's second half (where any transient has decayed
    most), the residual is split into ``n_blocks`` blocks, and the RMS of the first block
    is compared with the median RMS of the second half's blocks. A free response
    decaying from the start makes that ratio large; a settled record gives ~1.

    Parameters
    ----------
    table : DataFrame
        Long table with ``speed`` (rad/s), ``t`` (s) and the channels (m).
    channels : sequence of str
    n_blocks : int
        Blocks per record (each should hold a few dozen samples at least).

    Returns
    -------
    DataFrame
        One row per speed: ``speed``, ``ratio`` (the first block's, largest over the
        channels), ``transient`` (``ratio > TRANSIENT_RATIO``) and ``decayed_s`` (s from
        the record's start to the first block within 50 % of the tail's level; 0 for a
        settled record).
    """
    rows = []
    orders = tuple(ORDERS) + _EXTRA
    for w, g in table.groupby("speed", sort=True):
        t = g["t"].to_numpy()
        Y = g[list(channels)].to_numpy()
        n = t.size
        B = harmonic_basis(w * t, orders)
        half = slice(n // 2, n)
        coef, *_ = np.linalg.lstsq(B[half], Y[half], rcond=None)
        R = Y - B @ coef
        blocks = np.array_split(np.arange(n), n_blocks)
        rms = np.array([np.sqrt(np.mean(R[b] ** 2, axis=0)) for b in blocks])
        tail = np.maximum(np.median(rms[n_blocks // 2:], axis=0), 1e-300)
        per_block = np.max(rms / tail, axis=1)
        quiet = np.flatnonzero(per_block <= _QUIET_RATIO)
        decayed = float(t[blocks[quiet[0]][0]] - t[0]) if quiet.size else float(t[-1] - t[0])
        rows.append({"speed": float(w), "ratio": float(per_block[0]),
                     "decayed_s": decayed if per_block[0] > TRANSIENT_RATIO else 0.0,
                     "transient": bool(per_block[0] > TRANSIENT_RATIO)})
    return pd.DataFrame(rows)


def _window_features(w, t, Y, fs, orders):
    """Order vectors, standard errors and line energies of one window (all channels)."""
    n = t.size
    phi = w * t
    B = harmonic_basis(phi, tuple(orders) + _EXTRA)
    coef, *_ = np.linalg.lstsq(B, Y, rcond=None)
    R = Y - B @ coef
    dof = max(n - B.shape[1], 1)
    se = np.sqrt((R**2).sum(axis=0) / dof) * np.sqrt(2.0 / n)
    k = len(orders)
    vec = coef[1 : 1 + 2 * k : 2] - 1j * coef[2 : 2 + 2 * k : 2]  # (orders, channels)
    return vec, se, _line_energy(R, fs, w)


def record_features(record, channels, transient_s=0.5, orders=ORDERS):
    """Features of one record ``(speed, t, Y)``: keys, values and standard errors (lists).

    Separate from :func:`feature_arrays` so that a simulation thread can extract the
    features of its own record while the other thread integrates.
    """
    w, t, Y = record
    keys, vals, ses = [], [], []
    labels = [ORDER_LABELS.get(k, f"{k:g}x") for k in orders]
    fs = 1.0 / np.median(np.diff(t)) if t.size > 1 else 1.0
    for window, mask in (("transient", t < transient_s), ("steady", t >= transient_s)):
        if int(mask.sum()) < 32:
            continue
        vec, se, (amps, floor) = _window_features(w, t[mask], Y[mask], fs, orders)
        for c, ch in enumerate(channels):
            for i, lab in enumerate(labels):
                keys.append((w, window, ch, lab))
                vals.append(vec[i, c])
                ses.append(se[c])
            for lab, a in zip(NONSYNC_LABELS, amps[c], strict=True):
                keys.append((w, window, ch, lab))
                vals.append(a)
                ses.append(floor[c])
    return keys, vals, ses


def stack_features(parts):
    """Join :func:`record_features` of several records into aligned arrays.

    Returns ``keys`` (list of (speed, window, channel, feature)), complex values,
    standard errors and a boolean mask of the ``nonsync`` rows.
    """
    keys = [k for p in parts for k in p[0]]
    vals = np.array([v for p in parts for v in p[1]], dtype=complex)
    ses = np.array([v for p in parts for v in p[2]], dtype=float)
    nons = np.array([is_nonsync(k[3]) for k in keys], dtype=bool)
    return keys, vals, ses, nons


def feature_arrays(records, channels, transient_s=0.5, orders=ORDERS):
    """Features of ``records`` = [(speed, t, Y)] as aligned arrays (fast path).

    Returns ``keys`` (list of (speed, window, channel, feature)), complex values,
    standard errors and a boolean mask of the ``nonsync`` rows, always in the same
    order for the same speeds, windows and channels.
    """
    return stack_features([record_features(r, channels, transient_s, orders)
                           for r in records])


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
