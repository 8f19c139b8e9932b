"""Generate docs/api.md from the docstrings of the public API.

Run: python docs/gen_api.py   (the test suite runs it too, so it cannot rot)
"""

from __future__ import annotations

import importlib
import inspect
from pathlib import Path

#: Every public module: the package root and each module a user imports by name.
MODULES = ("sknarx", "sknarx.rotor", "sknarx.gap", "sknarx.bode", "sknarx.unbalance",
           "sknarx.datasets",
           "sknarx.reproduce",
           "sknarx.narx.validity", "sknarx.io", "sknarx.orders", "sknarx.plotting")

OUT = Path(__file__).resolve().parent / "api.md"


def _doc(obj) -> str:
    # getdoc follows the class hierarchy, so an override documents itself by its base
    return inspect.getdoc(obj) or "(undocumented)"


def render() -> str:
    parts = ["# API reference", "", "Generated from the docstrings by `docs/gen_api.py`.", ""]
    for mod in map(importlib.import_module, MODULES):
        parts += [f"## `{mod.__name__}`", "", _doc(mod), ""]
        for name in mod.__all__:
            obj = getattr(mod, name)
            if mod.__name__ != "sknarx" and getattr(obj, "__module__", "").startswith(
                    "sknarx") and name in getattr(__import__("sknarx"), "__all__", ()):
                continue  # documented once, under the package root
            if name.startswith("__") or not (inspect.isclass(obj) or inspect.isfunction(obj)):
                continue
            try:
                sig = str(inspect.signature(obj))
            except (TypeError, ValueError):
                sig = "(...)"
            parts += [f"### `{mod.__name__}.{name}{sig}`", "", "```text", _doc(obj), "```", ""]
            if inspect.isclass(obj):
                for meth, fn in inspect.getmembers(obj, inspect.isfunction):
                    if meth.startswith("_") or fn.__qualname__.split(".")[0] != obj.__name__:
                        continue
                    parts += [f"#### `{name}.{meth}{inspect.signature(fn)}`", "", "```text",
                              _doc(fn), "```", ""]
    return "\n".join(parts)


if __name__ == "__main__":
    import sys

    # document the checkout this script lives in, whichever copy pip's editable install
    # points at (a second clone re-points it)
    sys.path.insert(0, str(OUT.parents[1]))
    OUT.write_text(render())
    print(f"wrote {OUT}")
