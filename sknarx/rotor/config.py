"""Rotor description files (TOML, YAML or JSON)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from .parameters import RotorParameters

__all__ = ["load_config", "paper_rotor_from_config"]


def load_config(path) -> dict:
    """Parse a rotor file by its extension: .toml, .yaml/.yml or .json."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"No rotor file at {path}; check the path.")
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give the rotor file (.toml, .yaml or .json).")
    text = path.read_text()
    if path.suffix == ".toml":
        if sys.version_info >= (3, 11):
            import tomllib
        else:  # pragma: no cover
            import tomli as tomllib
        try:
            return tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"Rotor file {path} is not valid TOML: {exc}.") from exc
    if path.suffix in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError as exc:  # pragma: no cover
            raise ImportError("YAML rotor files need PyYAML: pip install pyyaml "
                              "(or use the .toml or .json form).") from exc
        return yaml.safe_load(text)
    if path.suffix == ".json":
        try:
            return json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"Rotor file {path} is not valid JSON: {exc}.") from exc
    raise ValueError(f"Rotor files are .toml, .yaml or .json, not {path.suffix!r}.")


def paper_rotor_from_config(cfg: dict) -> RotorParameters:
    """The paper's 12-DOF rotor with the ``[parameters]`` of a config overriding defaults."""
    model = cfg.get("rotor", {}).get("model", "paper")
    if model != "paper":
        raise ValueError(f"Rotor model {model!r} is not the paper's 12-DOF rotor.")
    return RotorParameters.from_dict(cfg.get("parameters", {}))
