"""Known speed-scheduled polynomial NARX systems for the tests."""

import numpy as np

from sknarx.narx.freerun import free_run
from sknarx.narx.terms import parse_terms


def simulate_system(terms, coef_fn, speeds, n=600, seed=0, u_scale=1.0, y_scale=1.0):
    """Noise-free data of ``y = sum theta_m(w) term_m`` driven by uniform random input.

    ``coef_fn(w)`` returns the coefficients at speed ``w``. The output is scaled by
    ``y_scale`` (which rescales the coefficients consistently, so the structure is
    unchanged) and the input by ``u_scale``.
    """
    exps, ny, nu = parse_terms(terms)
    rng = np.random.default_rng(seed)
    data = []
    for w in speeds:
        u = rng.uniform(-1, 1, n)
        y, at = free_run(u, np.asarray(coef_fn(w))[None, :], exps, ny, nu)
        assert at < 0, "test system diverged"
        data.append((u * u_scale, y * y_scale))
    return data


def scaled_coef_fn(terms, coef_fn, u_scale, y_scale):
    """Coefficients of the same system after u -> a u, y -> b y."""
    exps, ny, nu = parse_terms(terms)
    py = exps[:, :ny].sum(axis=1)
    pu = exps[:, ny:].sum(axis=1)
    factor = y_scale / (y_scale**py * u_scale**pu)
    return lambda w: np.asarray(coef_fn(w)) * factor
