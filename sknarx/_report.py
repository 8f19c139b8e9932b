"""What every HTML report shares: the page, tables, figures, quantities and provenance.

A report states where it came from (package version, commit, date, Python and
dependency versions, the command that regenerates it) and formats every number with
its unit; this module is the one place that does both.
"""

from __future__ import annotations

import datetime as _dt
import html
import math
import platform
import subprocess
from importlib import metadata
from pathlib import Path

from ._version import __version__

__all__ = ["dependency_versions", "provenance", "page", "table", "figure", "quantity",
           "at_bound", "value_range"]

DEPENDENCIES = ("numpy", "scipy", "scikit-learn", "pandas", "numba", "matplotlib", "joblib")

CSS = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;
color:#222}table{border-collapse:collapse;margin:0.6em 0;font-size:0.85em}
td,th{border:1px solid #ccc;padding:3px 7px;text-align:right;vertical-align:top}
th{background:#f3f3f3}td:first-child{text-align:left}.ok{color:#070;font-weight:bold}
.bad{color:#b00;font-weight:bold}.note{color:#555;font-size:0.9em}figure{margin:1em 0}
img{max-width:100%}figcaption{font-size:0.85em;color:#555}code{background:#f4f4f4;
padding:1px 4px}h2{border-bottom:1px solid #ddd}.prov{font-size:0.8em;color:#555}
table.nowrap td{white-space:nowrap}"""


def _commit() -> str | None:
    """The git commit of the package source, when it runs from a checkout."""
    try:
        here = Path(__file__).resolve().parent
        out = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=here,
                             capture_output=True, text=True, timeout=5)
        if out.returncode != 0:
            return None
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                               cwd=here, capture_output=True, text=True, timeout=5).stdout
        return out.stdout.strip() + ("+uncommitted changes" if dirty.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


def dependency_versions() -> dict:
    """Each of :data:`DEPENDENCIES`' installed version (None: not installed)."""
    deps = {}
    for name in DEPENDENCIES:
        try:
            deps[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            deps[name] = None
    return deps


def provenance(command: str) -> dict:
    """Version, commit, UTC date, Python and dependency versions, and the command."""
    deps = dependency_versions()
    return {
        "sknarx_version": __version__,
        "commit": _commit(),
        "date_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S"),
        "python": platform.python_version(),
        "dependencies": deps,
        "command": command,
    }


def provenance_html(p: dict) -> str:
    deps = ", ".join(f"{k} {v}" for k, v in p["dependencies"].items() if v)
    return (f'<p class="prov">sknarx {html.escape(p["sknarx_version"])}'
            f' (commit {html.escape(p["commit"] or "unknown: not run from a git checkout")});'
            f' {html.escape(p["date_utc"])} UTC; Python {html.escape(p["python"])}; '
            f"{html.escape(deps)}.<br>Regenerate with <code>{html.escape(p['command'])}</code>"
            "</p>")


def page(title: str, body: str, prov: dict) -> str:
    """A self-contained HTML page with the provenance under the title."""
    return (f'<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}'
            f"</title><style>{CSS}</style></head><body><h1>{html.escape(title)}</h1>"
            f"{provenance_html(prov)}{body}</body></html>")


def table(rows, headers, empty: str = "", nowrap: bool = False) -> str:
    """An HTML table of already-formatted cells; ``empty`` explains a table with no rows;
    ``nowrap`` keeps each cell on one line (model terms such as ``y(t-1)*u(t-3)``)."""
    rows = list(rows)
    if not rows:
        return f'<p class="note">{html.escape(empty or "Nothing to show.")}</p>'
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                   for r in rows)
    cls = ' class="nowrap"' if nowrap else ""
    return f"<table{cls}><tr>{head}</tr>{body}</table>"


def figure(path, caption: str = "") -> str:
    from .plotting import to_data_uri

    cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
    return (f'<figure><img src="{to_data_uri(path)}" alt="{html.escape(caption)}">{cap}'
            "</figure>")


def quantity(value, unit: str = "", digits: int = 3) -> str:
    """``1.23e-05 m``, ``1648 rpm``, ``0.872``: significant digits and the unit, never 16
    digits; plain notation between 1e-3 and 1e5, scientific outside."""
    if value is None:
        return "-"
    if isinstance(value, str):
        return value
    v = float(value)
    if not math.isfinite(v):
        return str(v)
    if v == 0 or 1e-3 <= abs(v) < 1e5:  # plain notation: 1648 rpm, 0.0345 m
        decimals = max(digits - 1 - math.floor(math.log10(abs(v))), 0) if v else 0
        text = f"{v:.{decimals}f}"
    else:
        text = f"{v:.{digits}g}"
    unit = unit.strip()
    return f"{text} {unit}" if unit and unit != "-" else text


def at_bound(value, lo, hi, scale="lin", tol=1e-3) -> str | None:
    """'lower' or 'upper' when a fitted value sits on its search bound, else None."""
    v = float(value)
    if scale == "log" and lo > 0 and v > 0:
        span = math.log(hi / lo)
        if math.log(v / lo) <= tol * span:
            return "lower"
        if math.log(hi / v) <= tol * span:
            return "upper"
        return None
    span = hi - lo
    if v - lo <= tol * span:
        return "lower"
    if hi - v <= tol * span:
        return "upper"
    return None


def value_range(lo, hi, unit: str, decimals: int = 1) -> str:
    """``90.0 rad/s`` for a single value, ``90.0-110.0 rad/s`` for a range."""
    a, b = f"{float(lo):.{decimals}f}", f"{float(hi):.{decimals}f}"
    return f"{a} {unit}" if a == b else f"{a}-{b} {unit}"


def percentage(value: float, decimals: int = 1) -> str:
    """A value given in per cent, with ``decimals`` decimals or as many more as keep it
    from reading as a whole number it is short of.

    Examples
    --------
    >>> percentage(99.99999988, 6), percentage(12.345), percentage(100.0, 2)
    ('99.9999999 %', '12.3 %', '100.00 %')
    """
    v = float(value)
    if not math.isfinite(v):
        return f"{v} %"
    text = f"{v:.{decimals}f}"
    while decimals < 15 and float(text) == round(float(text)) and abs(float(text)) > abs(v):
        decimals += 1
        text = f"{v:.{decimals}f}"
    return f"{text} %"
