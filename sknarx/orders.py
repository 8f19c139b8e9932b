"""Order (harmonic) analysis of rotor signals referenced to the shaft angle."""

from __future__ import annotations

import numpy as np

__all__ = ["order_components", "harmonic_basis", "spectrum"]


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
