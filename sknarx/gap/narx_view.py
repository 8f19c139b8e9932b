"""The NARX view of a gap: identify the same model class on measured and simulated data.

Which terms appear only in the measured model, and where the coefficient-versus-
speed curves of the shared terms part, is supporting evidence: a quadratic term
appearing in the measured model points to a 2x source, a shifted autoregressive
curve to a stiffness change, and so on.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..narx import IllConditionedWarning, SpeedScheduledNarx

__all__ = ["narx_view", "narx_view_of"]


def _records(table, channel, base):
    out = []
    for w, g in table.groupby("speed", sort=True):
        t = g["t"].to_numpy()
        u = base.m_O1 * base.e * w**2 * np.cos(w * t)  # the nominal unbalance force, N
        out.append((w, u, g[channel].to_numpy()))
    return out


def narx_view(measured, simulated, channel, base, ny=2, nu=2, degree=2, max_terms=6) -> dict:
    """Fit speed-scheduled NARX models to both tables and compare them."""
    models = {}
    for name, table in (("measured", measured), ("simulated", simulated)):
        rec = _records(table, channel, base)
        speeds = np.array([r[0] for r in rec])
        with warnings.catch_warnings():
            # a short record's terms are near-collinear: the view compares structures
            warnings.simplefilter("ignore", IllConditionedWarning)
            models[name] = SpeedScheduledNarx(
                ny=ny, nu=nu, degree=degree, esr=0.0, max_terms=max_terms, prune=False,
                speed_basis="spline").fit([(r[1], r[2]) for r in rec], speeds)
    m, s = models["measured"], models["simulated"]
    grid = np.linspace(*m.speed_range_, 50)
    common = [t for t in m.selected_terms_ if t in s.selected_terms_]
    curves = {}
    for term in common:
        cm = m.coefficients_at(grid)[:, m.selected_terms_.index(term)]
        cs = s.coefficients_at(grid)[:, s.selected_terms_.index(term)]
        scale = max(np.max(np.abs(cs)), 1e-300)
        curves[term] = float(np.max(np.abs(cm - cs)) / scale)
    nonlinear = [t for t in m.selected_terms_ if t not in s.selected_terms_ and
                 ("^" in t or "*" in t)]
    return {
        "channel": channel,
        "terms_measured": m.selected_terms_,
        "terms_simulated": s.selected_terms_,
        "only_measured": [t for t in m.selected_terms_ if t not in s.selected_terms_],
        "only_simulated": [t for t in s.selected_terms_ if t not in m.selected_terms_],
        "max_relative_coefficient_difference": curves,
        "reading": ("Nonlinear terms selected only for the measurement ("
                    + ", ".join(nonlinear) + "): a candidate harmonic source the simulator "
                    "lacks; whether it matters is the gap diagnosis's call, not this view's.")
        if nonlinear else "No nonlinear term is specific to the measured model.",
        "_models": models,
    }


def narx_view_of(result, measured, base) -> dict:
    """The NARX view of a :func:`~sknarx.gap.diagnose` result: measured records against
    the (updated) nominal rotor with the calibrated nuisance parameters, first channel."""
    import pandas as pd

    from .measured import check_measured
    from .sweep_model import SweepModel

    measured, _ = check_measured(measured, result["channels"])
    ch = result["channels"][0]
    # the rotor the diagnosis compared with: updated, and settled as the records were
    base = result.base if result.base is not None else base
    model = SweepModel(base=base, fs=result["sampling"]["fs_hz"],
                       n_samples=result["sampling"]["samples_per_step"], channels=(ch,),
                       settle_s=result.get("records", {}).get("simulation_settle_s", 0.0),
                       step_factor=result["settings"]["budget"]["step_factor"])
    speeds = sorted(result["split"]["train_speeds"] + result["split"]["heldout_speeds"])
    nuis = np.array(list(result["nuisance"]["calibrated"].values()))
    sim = pd.concat([pd.DataFrame({"speed": w, "t": t, ch: Y[:, 0]})
                     for w, t, Y in model.records(speeds, nuis)], ignore_index=True)
    return narx_view(measured, sim, ch, base)
