"""Order (harmonic) analysis of rotor signals referenced to the shaft angle.

:func:`order_components` fits a signal's shaft orders by least squares (exact for a
steady periodic response, free of an FFT bin's leakage). :func:`order_features` is the
common currency of the gap diagnosis: for each speed step, time window (``transient``:
the first ``transient_s`` seconds; ``steady``: the rest) and channel, the record is
fitted with a constant and the shaft orders 1/3x, 1/2x, 1x, 2x, 3x (plus 4x, 5x to keep
them out of the residual). Each order gives a complex vector ``V = A e^{i phase}``
(``x ~ A cos(k phi + phase)``) with a standard error from the residual; the residual's
*line energy* -- power in spectral lines standing above its white floor -- measures
non-synchronous content (sidebands, electrical lines, subharmonics not on the list)
while ignoring broadband noise. It is kept per band of shaft order
(``NONSYNC_BANDS``): a fixed-frequency line (mains pickup, a natural frequency ringing
down) walks across the bands as the speed changes, while a bearing's ball-passage line
stays in its band.
"""

from __future__ import annotations

import threading

import numpy as np
import pandas as pd

__all__ = ["order_components", "harmonic_basis", "spectrum", "ORDERS", "order_features",
           "ORDER_LABELS", "NONSYNC_BANDS", "NONSYNC_LABELS", "is_nonsync",
           "free_response_decay", "TRANSIENT_RATIO", "record_features", "stack_features",
           "feature_arrays"]


def harmonic_basis(phi, orders) -> np.ndarray:
    """Least-squares basis ``[1, cos(k phi), sin(k phi), ...]`` of shaft orders.

    Parameters
    ----------
    phi : ndarray (n,)
        Shaft angle, rad.
    orders : sequence of float
        Orders ``k`` (1 = once per revolution).

    Returns
    -------
    B : ndarray (n, 1 + 2 len(orders))
    """
    phi = np.asarray(phi, dtype=float)
    B = np.empty((phi.size, 1 + 2 * len(orders)))
    B[:, 0] = 1.0
    for i, k in enumerate(orders):
        B[:, 1 + 2 * i] = np.cos(k * phi)
        B[:, 2 + 2 * i] = np.sin(k * phi)
    return B


def order_components(x, phi, orders=(1, 2, 3)):
    """Amplitude (0-peak) and phase of shaft-synchronous orders by least squares.

    Fits ``x = c + sum_k A_k cos(k phi + phase_k)`` with ``phi`` the shaft angle
    (rad); exact for a steady periodic response and, unlike an FFT bin, free of
    leakage when the record is not an integer number of revolutions.

    Parameters
    ----------
    x : array-like (n,)
        Signal (e.g. displacement, m).
    phi : array-like (n,)
        Shaft angle, rad (``omega t`` at constant speed).
    orders : sequence of float
        Orders to fit (1 = once per revolution; 0.5 = half order).

    Returns
    -------
    amplitude : ndarray (len(orders),)
    phase : ndarray (len(orders),), rad, ``x ~ A cos(k phi + phase)``
    """
    x = np.asarray(x, dtype=float)
    coef, *_ = np.linalg.lstsq(harmonic_basis(phi, orders), x, rcond=None)
    a, b = coef[1::2], coef[2::2]
    return np.hypot(a, b), np.arctan2(-b, a)


def spectrum(x, fs, window="hann"):
    """One-sided amplitude spectrum (0-peak units of ``x``) and frequencies (Hz)."""
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    w = np.hanning(x.size) if window == "hann" else np.ones(x.size)
    X = np.fft.rfft(x * w)
    amp = 2.0 * np.abs(X) / w.sum()
    return np.fft.rfftfreq(x.size, 1.0 / fs), amp


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


def _line_energy(R, fs, omega, plan=None):
    """Amplitude of spectral lines above the white floor of residuals, per order band.

    ``R`` holds one residual per column. Returns the line amplitudes, shape
    ``(channels, bands)`` with the bands of ``NONSYNC_BANDS`` (units of ``R``), and the
    white-floor amplitude of one bin per channel. ``plan`` (a :class:`_WindowPlan` of
    the same length, sampling and speed) supplies the Hann window and each bin's band.
    """
    n, n_ch = R.shape
    nb = len(NONSYNC_LABELS)
    if n < 16:
        return np.zeros((n_ch, nb)), np.zeros(n_ch)
    win, band = (plan.hann, plan.band) if plan is not None else _spectral_plan(n, fs, omega)
    # all channels in one transform: each column is transformed exactly as on its own
    P = np.abs(np.fft.rfft(R * win[:, None], axis=0)) ** 2
    P = P[1:]
    level = np.median(P, axis=0) / np.log(2.0)  # exponential law of white periodogram bins
    thr = level * np.log(P.shape[0] / 1e-3)  # ~1e-3 false exceedances per record
    excess = np.where(P > thr, np.clip(P - level, 0.0, None), 0.0)
    per_band = np.stack([np.bincount(band, weights=excess[:, c], minlength=nb)[:nb]
                         for c in range(n_ch)])
    scale = 2.0 / (win.sum() ** 2)  # periodogram -> squared amplitude
    return np.sqrt(per_band * scale), np.sqrt(level * scale)


def _spectral_plan(n, fs, omega):
    """The Hann window of ``n`` samples and the order band of each periodogram bin
    (the DC bin left out) at speed ``omega`` rad/s."""
    order = np.arange(1, n // 2 + 1) * fs / n * 2 * np.pi / max(omega, 1e-12)
    return np.hanning(n), np.searchsorted(NONSYNC_BANDS, order, side="right") - 1


class _WindowPlan:
    """What the features of one window compute from its time axis and speed alone: the
    harmonic basis, the Hann window, each periodogram bin's band, and the rows' keys.

    A calibration simulates the same speeds on the same time grid thousands of times;
    built once per grid, these take a third off the features of a record (one
    1,000-sample, 6-channel window 0.68 -> 0.41 ms), and every number computed from
    them is bit for bit the same.
    """

    def __init__(self, w, window, t, fs, orders, channels):
        labels = [ORDER_LABELS.get(k, f"{k:g}x") for k in orders]
        self.n_orders = len(orders)
        self.B = harmonic_basis(w * t, tuple(orders) + _EXTRA)
        self.hann, self.band = _spectral_plan(t.size, fs, w)
        # one row per channel: the orders' vectors, then the bands' line amplitudes
        self.keys = [(w, window, ch, lab) for ch in channels
                     for lab in (*labels, *NONSYNC_LABELS)]
        self.nonsync = np.array([is_nonsync(k[3]) for k in self.keys], dtype=bool)


_PLANS: dict = {}
_PLANS_LOCK = threading.Lock()  # the simulation threads extract features concurrently
_MAX_PLANS = 64  # a 19-speed sweep's two windows need 38


def _window_plan(w, window, t, fs, orders, channels) -> _WindowPlan:
    key = (w, window, t.tobytes(), fs, tuple(orders), tuple(channels))
    plan = _PLANS.get(key)
    if plan is None:
        plan = _WindowPlan(w, window, t, fs, orders, channels)
        with _PLANS_LOCK:
            if len(_PLANS) >= _MAX_PLANS:  # the oldest plan makes room (dicts keep order)
                _PLANS.pop(next(iter(_PLANS)), None)
            _PLANS[key] = plan
    return plan


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


def _window_features(w, Y, fs, plan):
    """Order vectors, standard errors and line energies of one window (all channels),
    ``plan`` being its :class:`_WindowPlan`."""
    n, B = Y.shape[0], plan.B
    # lstsq, not a cached pseudo-inverse: the product rounds differently, and at 1e-11
    # the calibration's search already chooses another basin in places
    coef, *_ = np.linalg.lstsq(B, Y, rcond=None)
    R = Y - B @ coef
    dof = max(n - B.shape[1], 1)
    se = np.sqrt((R**2).sum(axis=0) / dof) * np.sqrt(2.0 / n)
    k = plan.n_orders
    vec = coef[1 : 1 + 2 * k : 2] - 1j * coef[2 : 2 + 2 * k : 2]  # (orders, channels)
    return vec, se, _line_energy(R, fs, w, plan)


def record_features(record, channels, transient_s=0.5, orders=ORDERS):
    """Features of one record ``(speed, t, Y)``: keys (a list), complex values, standard
    errors and the ``nonsync`` mask (arrays), one row per (window, channel, feature).

    Separate from :func:`feature_arrays` so that a simulation thread can extract the
    features of its own record while the other thread integrates.
    """
    w, t, Y = record
    keys, vals, ses, nons = [], [], [], []
    fs = 1.0 / np.median(np.diff(t)) if t.size > 1 else 1.0
    for window, mask in (("transient", t < transient_s), ("steady", t >= transient_s)):
        if int(mask.sum()) < 32:
            continue
        tw = t[mask]
        plan = _window_plan(w, window, tw, fs, orders, channels)
        vec, se, (amps, floor) = _window_features(w, Y[mask], fs, plan)
        keys.extend(plan.keys)
        # per channel: its orders' vectors, then its bands' amplitudes (plan.keys' order)
        vals.append(np.concatenate([vec.T, amps], axis=1).ravel())
        ses.append(np.concatenate([np.repeat(se[:, None], len(orders), axis=1),
                                   np.repeat(floor[:, None], amps.shape[1], axis=1)],
                                  axis=1).ravel())
        nons.append(plan.nonsync)
    if not vals:
        return keys, np.empty(0, complex), np.empty(0), np.empty(0, bool)
    return keys, np.concatenate(vals), np.concatenate(ses), np.concatenate(nons)


def stack_features(parts):
    """Join :func:`record_features` of several records into aligned arrays.

    Returns ``keys`` (list of (speed, window, channel, feature)), complex values,
    standard errors and a boolean mask of the ``nonsync`` rows.
    """
    keys = [k for p in parts for k in p[0]]
    if not parts:
        return keys, np.empty(0, complex), np.empty(0), np.empty(0, bool)
    return (keys, np.concatenate([np.asarray(p[1], dtype=complex) for p in parts]),
            np.concatenate([np.asarray(p[2], dtype=float) for p in parts]),
            np.concatenate([np.asarray(p[3], dtype=bool) for p in parts]))


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
