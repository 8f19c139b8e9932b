"""Settings of the paper's Case 1, as one documented object."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["PaperCase"]


@dataclass(frozen=True)
class PaperCase:
    """Everything that determines the reproduction's numbers.

    Sampling rate: the paper does not give one. ``fs = 1000 Hz`` puts 23-77
    samples in a revolution over 81.7-276.5 rad/s (13-44 Hz), keeps the
    bearings' ball-pass component (3.08x, up to 136 Hz) and 3x well below
    Nyquist, and keeps ``omega * dt`` in 0.08-0.28 rad, where three output lags
    stay distinguishable (the selected regressors' condition number is ~1e5);
    at 10 kHz they would be near-collinear (~1e9) and the ERR ranking
    numerically meaningless. 81,921 samples are then 82 s per speed.
    """

    paper_critical_speed: float = 144.5  # the paper's response peak, rad/s (its Fig. 2)
    speeds: tuple = tuple(np.linspace(81.7, 276.5, 19).round(6))
    validation_speeds: tuple = (100.5, 138.2, 213.6)
    figure_speeds: tuple = (94.2, 144.5, 250.0)
    fs: float = 1000.0
    n_samples: int = 81921
    settle: float = 2.0
    output: str = "xO1"
    ny: int = 3
    nu: int = 3
    degree: int = 3
    max_terms: int = 10
    esr: float = 0.0
    coef_degree: int = 3
    validation_samples: int = 16384
    cv_samples: int = 16384
    curve_speeds: tuple = tuple(np.arange(50.0, 320.0 + 1e-9, 2.0))
    runup: tuple = (80.0, 280.0, 20.0)  # from, to (rad/s), duration (s)
    bands: tuple = ((81.7, 130.0), (130.0, 180.0), (180.0, 276.5))  # Ma et al. style
    validity_lags: int = 20  # largest lag of the residual correlation tests (samples)
    n_jobs: int = 2
    seed: int = 0
    notes: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The settings as plain JSON types (tuples as lists), as in ``metrics.json``."""
        d = asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
