"""Generate docs/api.md from the docstrings of the public API.

Run: python docs/gen_api.py   (the test suite runs it too, so it cannot rot)
"""

from __future__ import annotations

import inspect
from pathlib import Path

import sknarx
import sknarx.rotor

OUT = Path(__file__).resolve().parent / "api.md"


def _doc(obj) -> str:
    return inspect.cleandoc(obj.__doc__ or "(undocumented)")


def render() -> str:
    parts = ["# API reference", "", "Generated from the docstrings by `docs/gen_api.py`.", ""]
    for mod in (sknarx, sknarx.rotor):
        parts += [f"## `{mod.__name__}`", "", _doc(mod), ""]
        for name in mod.__all__:
            obj = getattr(mod, name)
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
    OUT.write_text(render())
    print(f"wrote {OUT}")
