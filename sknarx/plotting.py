"""Thin matplotlib helpers shared by the reports (headless: the Agg backend)."""

from __future__ import annotations

import base64
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .io import write_atomic  # noqa: E402

__all__ = ["plt", "save", "legend_below", "to_data_uri", "correlation_tests_figure"]

plt.rcParams.update({
    "figure.dpi": 110,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "font.size": 9,
})


def save(fig, path, rect=(0, 0, 1, 1)) -> Path:
    """Write ``fig`` as PNG and close it; the axes are laid out inside ``rect`` (figure
    fractions: room left outside it for a figure legend)."""
    fig.tight_layout(rect=rect)
    path = write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))
    plt.close(fig)
    return path


def legend_below(fig, ax=None, handles=None, ncol=3, fontsize=7) -> tuple:
    """One legend for the figure, centred below the axes so that it covers no data.

    The entries are ``handles`` or those of ``ax`` (the figure's first axes by default).
    Returns the ``rect`` to pass to :func:`save`: the axes' area above the legend.
    """
    if handles is None:
        handles, _ = (ax or fig.axes[0]).get_legend_handles_labels()
    ncol = max(1, min(ncol, len(handles)))
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=fontsize,
               frameon=False)
    rows = -(-len(handles) // ncol)
    # one legend row takes about 0.17 in at 7 pt, plus a margin of 0.1 in
    bottom_in = 0.1 + 0.17 * rows * fontsize / 7
    return (0, min(0.4, bottom_in / fig.get_figheight()), 1, 1)


def to_data_uri(path) -> str:
    """A PNG file as a ``data:`` URI, so an HTML report is one self-contained file."""
    data = Path(path).read_bytes()
    return "data:image/png;base64," + base64.b64encode(data).decode()


_TEST_LABELS = {
    "phi_ee": r"$\phi_{ee}(\tau)$",
    "phi_ue": r"$\phi_{ue}(\tau)$",
    "phi_e_eu": r"$\phi_{e(eu)}(\tau)$",
    "phi_u2_e": r"$\phi_{u^{2\prime}e}(\tau)$",
    "phi_u2_e2": r"$\phi_{u^{2\prime}e^2}(\tau)$",
}


def correlation_tests_figure(tables: dict, scope: str = "pooled"):
    """The five correlation tests of one or more models, one row of panels per model.

    Parameters
    ----------
    tables : dict
        ``{label: table}`` with tables from
        :func:`sknarx.narx.validity.correlation_tests`.
    scope : {'pooled', 'per_speed'}
        ``per_speed`` overlays every speed in grey.

    Returns
    -------
    fig : matplotlib Figure
    """
    tests = list(_TEST_LABELS)
    fig, axes = plt.subplots(len(tables), len(tests), figsize=(2.4 * len(tests),
                                                              2.0 * len(tables) + 0.4),
                             squeeze=False)
    for row, (label, table) in zip(axes, tables.items(), strict=True):
        part = table[table.scope == scope]
        for ax, test in zip(row, tests, strict=True):
            for _, g in part[part.test == test].groupby("speed", dropna=False):
                ax.plot(g.lag, g.value, "-", lw=0.8,
                        color="k" if scope == "pooled" else "0.4")
                band = float(g.band.iloc[0])
                ax.axhspan(-band, band, color="tab:blue", alpha=0.12, lw=0)
            ax.axhline(0, color="0.5", lw=0.5)
            sel = part[part.test == test]
            top = max(float(np.nanmax(np.abs(sel.value))), float(sel.band.max()))
            ax.set_ylim(-1.15 * top, 1.15 * top)  # a good model's correlations are tiny
            ax.set_title(_TEST_LABELS[test], fontsize=9)
            ax.set_xlabel("lag (samples)", fontsize=8)
        row[0].set_ylabel(f"{label}\ncorrelation", fontsize=8)
    for ax in axes.ravel():
        ax.tick_params(labelsize=7)
    fig.suptitle("Model validity: residual correlations (shaded: 95 % band)", fontsize=9)
    return fig
