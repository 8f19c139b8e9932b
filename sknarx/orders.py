"""Order (harmonic) analysis of rotor signals referenced to the shaft angle."""

from __future__ import annotations

import numpy as np

__all__ = ["order_components", "spectrum"]


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
    phi = np.asarray(phi, dtype=float)
    cols = [np.ones_like(phi)]
    for k in orders:
        cols += [np.cos(k * phi), np.sin(k * phi)]
    B = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(B, x, rcond=None)
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
