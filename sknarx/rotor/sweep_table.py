"""The sweep table on disk: parquet or CSV with the settings as metadata, resumable.

A sweep written to a *directory* keeps one file per finished speed plus
``settings.json``; each file is written to a temporary name and renamed, so an
interrupted sweep leaves only complete files, and a rerun with the same settings
simulates only the missing speeds. A sweep saved to a single ``.parquet`` file
carries its settings in the parquet key-value metadata; a ``.csv`` file gets a
``<name>.settings.json`` sidecar.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from ..io import write_atomic

__all__ = ["save_sweep", "load_sweep", "SweepStore"]

_META_KEY = b"sknarx.settings"


def _have_parquet() -> bool:
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return False
    return True


def save_sweep(df: pd.DataFrame, path, settings: dict | None = None):
    """Write a sweep table to ``.parquet`` or ``.csv`` with its settings."""
    path = Path(path)
    settings = settings or df.attrs.get("settings", {})
    if path.suffix == ".parquet":
        if not _have_parquet():
            raise ImportError("Writing parquet needs pyarrow: pip install 'sknarx[parquet]'.")
        import pyarrow as pa
        import pyarrow.parquet as pq

        def write(tmp):
            table = pa.Table.from_pandas(df, preserve_index=False)
            meta = dict(table.schema.metadata or {})
            meta[_META_KEY] = json.dumps(settings).encode()
            pq.write_table(table.replace_schema_metadata(meta), tmp)

        write_atomic(path, write)
    elif path.suffix == ".csv":
        write_atomic(path, lambda tmp: df.to_csv(tmp, index=False, float_format="%.17g"))
        side = path.with_name(path.name + ".settings.json")
        write_atomic(side, lambda tmp: Path(tmp).write_text(json.dumps(settings, indent=1)))
    else:
        raise ValueError(f"Unknown sweep file type {path.suffix!r}: use .parquet or .csv.")


def load_sweep(path) -> pd.DataFrame:
    """Read a sweep table (file or resumable directory); settings in ``df.attrs['settings']``."""
    path = Path(path)
    if path.is_dir():
        return SweepStore(path).load()
    if not path.exists():
        raise FileNotFoundError(f"No sweep table at {path}.")
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        meta = (table.schema.metadata or {}).get(_META_KEY)
        df = table.to_pandas()
        df.attrs["settings"] = json.loads(meta) if meta else {}
    elif path.suffix == ".csv":
        df = pd.read_csv(path, dtype=float)  # sweep tables are all-float
        side = path.with_name(path.name + ".settings.json")
        df.attrs["settings"] = json.loads(side.read_text()) if side.exists() else {}
    else:
        raise ValueError(f"Unknown sweep file type {path.suffix!r}: use .parquet or .csv.")
    return df


class SweepStore:
    """A directory holding one file per finished speed and the sweep's settings."""

    def __init__(self, path, fmt: str | None = None):
        self.path = Path(path)
        self.fmt = fmt or ("parquet" if _have_parquet() else "csv")

    def _file(self, speed: float) -> Path:
        return self.path / f"speed_{speed:.9f}.{self.fmt}"

    def open(self, settings: dict):
        """Start or resume; refuses to mix runs made with different settings."""
        self.path.mkdir(parents=True, exist_ok=True)
        meta = self.path / "settings.json"
        if meta.exists():
            old = json.loads(meta.read_text())
            if old != json.loads(json.dumps(settings)):
                raise ValueError(
                    f"{self.path} holds a sweep made with different settings; use another "
                    "directory or delete it to start over."
                )
        else:
            write_atomic(meta, lambda tmp: Path(tmp).write_text(json.dumps(settings, indent=1)))

    def done(self, speed: float) -> bool:
        return self._file(speed).exists()

    def write(self, speed: float, df: pd.DataFrame):
        save_sweep(df, self._file(speed), {})
        side = self._file(speed).with_name(self._file(speed).name + ".settings.json")
        if side.exists():  # the directory's settings.json is the one that counts
            side.unlink()

    def read(self, speed: float) -> pd.DataFrame:
        return load_sweep(self._file(speed))

    def load(self) -> pd.DataFrame:
        files = sorted(self.path.glob(f"speed_*.{self.fmt}"))
        if not files:
            raise FileNotFoundError(f"No finished speeds in {self.path}.")
        df = pd.concat([load_sweep(f) for f in files], ignore_index=True)
        df = df.sort_values(["speed", "t"], kind="stable").reset_index(drop=True)
        df.attrs["settings"] = json.loads((self.path / "settings.json").read_text())
        return df
