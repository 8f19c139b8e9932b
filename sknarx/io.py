"""Files: tables users hand in, fitted models as JSON (exact round trip, no pickle),
JSON-safe values."""

from __future__ import annotations

import csv
import logging
from pathlib import Path

import pandas as pd

from ._atomic import write_atomic, write_text_atomic
from ._json import json_safe

__all__ = ["read_table", "write_atomic", "write_text_atomic", "model_to_json",
           "model_from_json", "json_safe"]

logger = logging.getLogger(__name__)

TABLE_SUFFIXES = (".csv", ".parquet")


def read_table(path, what="table", nrows=None) -> pd.DataFrame:
    """Read a user's CSV or parquet file, with errors that name the problem and the fix.

    The CSV delimiter is sniffed (``,``, ``;``, tab or ``|``), so files written by
    spreadsheet programs in locales that use ``;`` read as they are.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file is, for messages ("measured data", "Bode file").
    nrows : int, optional
        Read only the header and this many rows.

    Raises
    ------
    FileNotFoundError, ValueError, ImportError
        With one-line messages naming the file: no such file, a folder, an unsupported
        suffix, an empty file, a header without rows, an unparseable CSV, a file that is
        not UTF-8 text, an unreadable parquet file, a parquet file without pyarrow.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{what}: no file at {path}; check the path.")
    if path.is_dir():
        raise ValueError(f"{what}: {path} is a folder; give the data file inside it.")
    if path.suffix.lower() not in TABLE_SUFFIXES:
        raise ValueError(f"{what}: {path.name} is a {path.suffix or 'suffix-less'} file; "
                         "save it as .csv (comma- or semicolon-separated) or .parquet.")
    if path.stat().st_size == 0:
        raise ValueError(f"{what}: {path} is empty; expected a header row and data rows.")
    if path.suffix.lower() == ".parquet":
        df = _read_parquet(path, what)
    else:
        with open(path, newline="", encoding="utf-8-sig", errors="replace") as fh:
            first = fh.readline()
        try:
            sep = csv.Sniffer().sniff(first, delimiters=",;\t|").delimiter
        except csv.Error:
            sep = ","
        if sep != ",":
            logger.debug("reading %s with delimiter %r", path, sep)
        try:
            df = pd.read_csv(path, sep=sep, nrows=nrows, encoding="utf-8-sig")
        except pd.errors.ParserError as exc:
            line = " ".join(str(exc).split())
            raise ValueError(f"{what}: {path} is not a well-formed CSV ({line}); every row "
                             "needs as many fields as the header.") from exc
        except pd.errors.EmptyDataError as exc:
            raise ValueError(f"{what}: {path} has no header row.") from exc
        except UnicodeDecodeError as exc:
            raise ValueError(f"{what}: {path} is not UTF-8 text (byte {exc.start} is "
                             f"0x{exc.object[exc.start]:02x}); save it as a UTF-8 CSV or as "
                             ".parquet.") from exc
    df.columns = [str(c).strip() for c in df.columns]
    if len(df) == 0 and nrows != 0:
        raise ValueError(f"{what}: {path} has a header ({', '.join(df.columns[:8])}) but no "
                         "data rows.")
    return df


def _read_parquet(path, what) -> pd.DataFrame:
    try:
        return pd.read_parquet(path)
    except ImportError as exc:
        raise ImportError(f"{what}: reading {path.name} needs pyarrow; install it with "
                          'pip install "sknarx[parquet]", or save the table as .csv.') from exc
    except (ValueError, OSError) as exc:  # pyarrow's ArrowInvalid is a ValueError
        line = " ".join(str(exc).split())[:200]
        raise ValueError(f"{what}: {path} is not a readable parquet file ({line}); "
                         "write it again with pandas' to_parquet or save it as .csv.") from exc


def model_to_json(model, path=None) -> str:
    """JSON text of a fitted :class:`~sknarx.SpeedScheduledNarx`; also written to ``path``.

    The estimator owns its format (:meth:`~sknarx.SpeedScheduledNarx.to_json`).
    """
    if not hasattr(model, "to_json") or not hasattr(model, "coef_poly_"):
        raise ValueError("Only a fitted SpeedScheduledNarx can be exported.")
    return model.to_json(path)


def model_from_json(source):
    """Rebuild a fitted model from JSON text or a path to a JSON file."""
    from .narx.scheduling import SpeedScheduledNarx

    return SpeedScheduledNarx.from_json(source)
