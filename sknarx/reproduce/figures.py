"""Figures of the reproduction, numbered as in the paper where they correspond."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.ticker import FuncFormatter

from ..orders import spectrum
from ..plotting import correlation_tests_figure, legend_below, plt, save

MODEL_STYLE = {
    "paper": dict(color="tab:red", ls="--", label="paper's method (steady data, cubic)"),
    "improved": dict(color="tab:blue", ls="-", label="from-rest data, cubic"),
    "improved-spline": dict(color="tab:green", ls="-", label="from-rest data, spline"),
    "single-speed": dict(color="tab:purple", ls=":", label="single-speed NARX"),
    "per-band": dict(color="tab:orange", ls="-.", label="per-band NARX (Ma et al.)"),
}


def make_figures(st, out: Path) -> dict:
    """Write every figure; returns ``{key: path}``."""
    out = Path(out)
    c = st.case
    figs = {}
    um = 1e3  # m -> mm

    fig, ax = plt.subplots(figsize=(6, 3.4))
    ax.plot(st.curve.speed, st.curve.amplitude * um, "k-", label="nonlinear (time simulation)")
    ax.plot(st.curve.speed, st.curve.linear_amplitude * um, "c--", lw=1,
            label="linearised bearings")
    ax.axvline(st.critical_speed, color="r", lw=0.8)
    ax.annotate(f"peak {st.critical_speed:.1f} rad/s\n(paper 144.5)",
                (st.critical_speed, st.curve.amplitude.max() * um), xytext=(10, -30),
                textcoords="offset points", fontsize=8)
    ax.set(xlabel="speed (rad/s)", ylabel=f"{c.output} amplitude (mm)",
           title="Fig. 2 - amplitude response of disk O1, x")
    ax.legend(fontsize=8)
    figs["fig2"] = save(fig, out / "fig2_amplitude_curve.png")

    wf = st.waterfall.pivot_table(index="speed", columns="frequency", values="amplitude")
    fig, ax = plt.subplots(figsize=(6.5, 4.0))
    level = np.log10(wf.to_numpy() * um + 1e-12)
    top = np.nanmax(level)
    mesh = ax.pcolormesh(wf.columns.to_numpy(), wf.index.to_numpy(), level, shading="nearest",
                         cmap="viridis", vmin=top - 5, vmax=top)
    fig.colorbar(mesh, ax=ax, label="log10 amplitude (mm)")
    w = wf.index.to_numpy()
    for k, style in ((1, "-"), (2, "--"), (3, ":")):
        ax.plot(k * w / (2 * np.pi), w, "w", ls=style, lw=0.8, alpha=0.8, label=f"{k}x")
    ax.set(xlabel="frequency (Hz)", ylabel="speed (rad/s)",
           xlim=(0, float(wf.columns.max())),
           title="Fig. 3 - waterfall of disk O1, x (5 decades shown)")
    ax.legend(fontsize=7, loc="lower right")
    ax.grid(False)
    figs["fig3"] = save(fig, out / "fig3_waterfall.png")

    for n, (w, run) in zip((4, 5, 6), st.figure_runs.items(), strict=True):
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(8, 2.8))
        last = run.iloc[-400:]
        a1.plot(last.t, last[c.output] * um, "k", lw=0.8)
        a1.set(xlabel="t (s)", ylabel=f"{c.output} (mm)", title=f"(a) time, {w} rad/s")
        f, a = spectrum(run[c.output].to_numpy(), c.fs)
        a2.semilogy(f, a * um, "k", lw=0.8)
        fr = w / (2 * np.pi)
        for k in (1, 2, 3):
            a2.axvline(k * fr, color="r", lw=0.5, ls=":")
        a2.set(xlim=(0, 200), ylim=(1e-7, None), xlabel="frequency (Hz)",
               ylabel="amplitude (mm)", title=f"(b) spectrum (1x = {fr:.1f} Hz)")
        figs[f"fig{n}"] = save(fig, out / f"fig{n}_response_{w:g}.png")

    for n, w in zip((8, 9, 10), c.validation_speeds, strict=True):
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(8.5, 3.4))
        tr = st.validation_traces[("improved-spline", float(w))]
        t, y, half = tr["t"], tr["y"], tr["half"]
        sl = slice(half, half + 300)
        a1.plot(t[sl], y[sl] * um, "k", lw=2, alpha=0.4, label="simulator (true)")
        for name in ("improved-spline", "paper"):
            trm = st.validation_traces[(name, float(w))]
            a1.plot(t[sl], trm["y_rest"][sl] * um, lw=0.9, **_style(name))
        a1.set(xlabel="t (s)", ylabel=f"{c.output} (mm)", title=f"(a) time, {w} rad/s")
        rect = legend_below(fig, a1)  # inside (a) it covered the traces
        f, a = spectrum(y[half:], c.fs)
        a2.semilogy(f, a * um, "k", lw=2, alpha=0.4)
        for name in ("improved-spline", "paper"):
            yh = st.validation_traces[(name, float(w))]["y_rest"][half:]
            if np.all(np.isfinite(yh)):
                fh, ah = spectrum(yh, c.fs)
                a2.semilogy(fh, ah * um, lw=0.8, **_style(name, label=False))
        a2.set(xlim=(0, 200), ylim=(1e-7, None), xlabel="frequency (Hz)",
               ylabel="amplitude (mm)", title="(b) spectrum")
        figs[f"fig{n}"] = save(fig, out / f"fig{n}_validation_{w:g}.png", rect=rect)

    fig, ax = plt.subplots(figsize=(6.5, 3.4))
    for name, g in st.cv.groupby("method"):
        ax.semilogy(g.held_out_speed, g.nrmse_from_rest, marker="o", ms=3, **_style(name))
    ax.axvline(st.critical_speed, color="r", lw=0.8)
    ax.set(xlabel="held-out speed (rad/s)", ylabel="free-run NRMSE from rest",
           title="Leave-one-speed-out cross-validation")
    ax.legend(fontsize=7)
    figs["cv"] = save(fig, out / "cv_error_vs_speed.png")

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5.4), sharex=True)
    r = st.runup
    for name in ("improved-spline", "paper"):
        a1.plot(r["t"], r[name] * um, lw=0.5, **_style(name))
    # the truth last and on top, so the models' traces do not hide it
    a1.plot(r["t"], r["y"] * um, "k", lw=0.5, label="simulator (true)", zorder=5)
    a1.set(ylabel=f"{c.output} (mm)", title="Run-up through the critical speed")
    for name in ("improved-spline", "improved", "paper"):
        a2.semilogy(r["t"], np.abs(r[name] - r["y"]) * um + 1e-9, lw=0.5, **_style(name))
    a2.set(xlabel="t (s)", ylabel="|model - true| (mm)")
    ax2 = a1.twinx()
    ax2.plot(r["t"], r["speed"], "r", lw=0.8, label="speed (right axis)")
    ax2.set_ylabel("speed (rad/s)", color="r")
    # one legend for both panels, below them, covering no data
    handles = {}
    for ax in (a1, ax2, a2):
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    figs["runup"] = save(fig, out / "runup.png",
                         rect=legend_below(fig, handles=list(handles.values())))

    model = st.models["improved"]
    spl = st.models["improved-spline"]
    names = model.selected_terms_
    fig, axes = plt.subplots(2, 5, figsize=(12, 4.4))
    grid = np.linspace(min(c.speeds), max(c.speeds), 200)
    cub, cub_sd = model.coefficients_at(grid, return_std=True)
    sp, sp_sd = spl.coefficients_at(grid, return_std=True)
    for ax, term in zip(axes.ravel(), names, strict=False):
        j = names.index(term)
        ax.errorbar(c.speeds, model.coef_per_speed_[term],
                    yerr=1.96 * model.coef_std_err_per_speed_[term], fmt="ko", ms=3,
                    elinewidth=0.6, capsize=1.5)
        ax.plot(grid, cub[:, j], "b-", lw=0.8)
        ax.fill_between(grid, cub[:, j] - 1.96 * cub_sd[:, j], cub[:, j] + 1.96 * cub_sd[:, j],
                        color="b", alpha=0.15, lw=0)
        if term in spl.selected_terms_:
            k = spl.selected_terms_.index(term)
            ax.plot(grid, sp[:, k], "g-", lw=0.8)
            ax.fill_between(grid, sp[:, k] - 1.96 * sp_sd[:, k], sp[:, k] + 1.96 * sp_sd[:, k],
                            color="g", alpha=0.15, lw=0)
        _scaled_title(ax, term, model.coef_per_speed_[term])
        ax.tick_params(labelsize=6)
    fig.suptitle("Coefficients against speed: per-speed (dots, 95 % intervals), cubic (blue) "
                 "and spline (green) with 95 % confidence bands", fontsize=9)
    figs["coefficients"] = save(fig, out / "coefficients_vs_speed.png")

    if st.validity:
        fig = correlation_tests_figure({_style(k)["label"]: st.validity[k]
                                        for k in ("improved-spline", "paper")
                                        if k in st.validity})
        figs["validity"] = save(fig, out / "validity_tests.png")

    fig, ax = plt.subplots(figsize=(6, 3.6))
    for (_mode, whirl), g in st.campbell.groupby(["mode", "whirl"]):
        ax.plot(g.speed, g.frequency, "b-" if whirl == "forward" else "m-", lw=1)
    top = float(st.campbell.speed.max())
    ax.plot([0, top], [0, top], "k:", lw=1, label="1x")
    ax.plot([0, top], [0, 2 * top], "k--", lw=0.6, label="2x")
    crossings = [w for w in np.atleast_1d(st.linear_critical_speeds) if w <= top]
    ax.plot(crossings, crossings, "ro", ms=6, mfc="none",
            label="1x crossings (critical speeds)")
    for w in crossings:
        ax.annotate(f"{w:.0f} rad/s", (w, w), xytext=(6, -12), textcoords="offset points",
                    fontsize=7, color="r")
    ax.set(ylim=(0, 1000), xlim=(0, top), xlabel="speed (rad/s)",
           ylabel="natural frequency (rad/s)",
           title="Campbell diagram (forward whirl blue, backward magenta)")
    ax.legend(fontsize=7, loc="upper left")
    figs["campbell"] = save(fig, out / "campbell.png")
    return figs


def _scaled_title(ax, title, values) -> int:
    """Title ``ax`` and put the values' power of ten into the title ("u(t-3) (x 1e-8)")
    instead of an offset label over the axes, where it collides with the title; returns
    the power (0: none shown)."""
    ax.yaxis.get_major_formatter().set_useOffset(False)
    top = float(np.nanmax(np.abs(values))) if len(values) else 0.0
    power = int(np.floor(np.log10(top))) if top > 0 and np.isfinite(top) else 0
    if abs(power) < 3:
        ax.set_title(title, fontsize=8)
        return 0
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _, p=power: f"{v / 10 ** p:g}"))
    ax.set_title(f"{title}  (x 1e{power})", fontsize=8)
    return power


def _style(name, label=True):
    s = dict(MODEL_STYLE.get(name, dict(label=name)))
    if not label:
        s.pop("label", None)
    return s
